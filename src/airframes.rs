//! `scan --airframes FILE.toml`: which airframe each log or board belongs to, for a fleet's
//! history (`history` groups by airframe, else by board id, else by system id).
//!
//! ```toml
//! [[airframe]]
//! name = "quad-07"
//! logs = ["archive/quad07/**/*.tlog"]          # glob patterns of the logs' paths
//! boards = ["mcu 003A002D 3138510F 33393935"]  # board ids, as the rows' board_uid (or the
//!                                               # boot banner "CubeOrange 003A002D ...")
//! ```
//!
//! A log's airframe is the first entry, in file order, that names its path or its vehicle's
//! board; a log that two entries name is said (the first wins). Patterns match the path as
//! `scan` names it: as given on its command line, or the directory given joined with the
//! names under it (`scan ./archive` gives `./archive/...`); `*` stays within one directory,
//! `**` crosses them. In a log of several vehicles the name its path matched is given to
//! each as `NAME sysid N`.

use crate::toml_file::{TomlFileError, parse, read_at_most};
use serde::Deserialize;
use std::path::Path;

/// `*` and `?` do not cross a `/`; `**` does.
const MATCH: glob::MatchOptions = glob::MatchOptions {
    case_sensitive: true,
    require_literal_separator: true,
    require_literal_leading_dot: false,
};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    #[serde(default)]
    airframe: Vec<Entry>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    name: String,
    #[serde(default)]
    logs: Vec<String>,
    #[serde(default)]
    boards: Vec<String>,
}

#[derive(Debug)]
struct Airframe {
    name: String,
    logs: Vec<glob::Pattern>,
    boards: Vec<String>,
}

/// The mapping, its patterns compiled.
#[derive(Debug, Default)]
pub struct Airframes {
    entries: Vec<Airframe>,
}

impl Airframes {
    pub fn load(path: &Path) -> Result<Self, TomlFileError> {
        let label = path.display().to_string();
        let bytes = read_at_most(path, crate::toml_file::MAX_TOML_BYTES, "an airframes file")
            .map_err(|reason| TomlFileError::Io {
                path: label.clone(),
                reason,
            })?;
        let text = String::from_utf8_lossy(&bytes);
        Self::parse(&text, &label)
    }

    pub fn parse(text: &str, label: &str) -> Result<Self, TomlFileError> {
        let file: File = parse(text, label, |f: &File| {
            if f.airframe.is_empty() {
                return Err("no [[airframe]] entry".into());
            }
            for e in &f.airframe {
                if e.name.trim().is_empty() {
                    return Err("airframe: a name is empty".into());
                }
                if e.logs.is_empty() && e.boards.is_empty() {
                    return Err(format!(
                        "airframe {}: neither logs nor boards name anything",
                        e.name
                    ));
                }
                if let Some((p, err)) = e
                    .logs
                    .iter()
                    .find_map(|p| glob::Pattern::new(p).err().map(|err| (p, err)))
                {
                    return Err(format!("airframe {}: logs: `{p}`: {err}", e.name));
                }
            }
            Ok(())
        })?;
        let entries = file
            .airframe
            .into_iter()
            .map(|e| Airframe {
                name: e.name,
                // Checked by the validation above.
                logs: e
                    .logs
                    .iter()
                    .filter_map(|p| glob::Pattern::new(p).ok())
                    .collect(),
                // As the rows give it: a banner ("CubeOrange 003A002D ...") as its MCU id.
                boards: e
                    .boards
                    .iter()
                    .map(|b| {
                        crate::telemetry::identity::from_banner(b)
                            .unwrap_or_else(|| b.trim().to_string())
                    })
                    .collect(),
            })
            .collect();
        Ok(Self { entries })
    }

    /// The airframes that name this log or board, in file order.
    pub fn names_for(&self, log: &Path, board_uid: Option<&str>) -> Vec<&str> {
        self.entries
            .iter()
            .filter(|a| {
                a.logs.iter().any(|p| p.matches_path_with(log, MATCH))
                    || board_uid.is_some_and(|b| a.boards.iter().any(|x| x == b))
            })
            .map(|a| a.name.as_str())
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_log_is_named_by_its_path_or_its_board_the_first_entry_first() {
        let a = Airframes::parse(
            r#"
[[airframe]]
name = "quad-07"
logs = ["archive/quad07/*.tlog"]
[[airframe]]
name = "hexa-01"
boards = ["CubeOrange 003A002D 3138510F 33393935"]
logs = ["archive/*/shared.tlog"]
"#,
            "t.toml",
        )
        .unwrap();
        let p = Path::new;
        assert_eq!(a.names_for(p("archive/quad07/f1.tlog"), None), ["quad-07"]);
        assert_eq!(
            a.names_for(p("elsewhere/x.bin"), Some("mcu 003A002D 3138510F 33393935")),
            ["hexa-01"]
        );
        assert_eq!(
            a.names_for(p("archive/quad07/shared.tlog"), None),
            ["quad-07", "hexa-01"]
        );
        assert!(a.names_for(p("other/f.tlog"), Some("X 1 2 3")).is_empty());
        assert!(
            a.names_for(p("archive/quad07/old/f1.tlog"), None)
                .is_empty(),
            "* stays within a directory"
        );
    }

    #[test]
    fn bad_files_are_errors_with_their_reason() {
        for (text, why) in [
            ("", "no [[airframe]]"),
            ("[[airframe]]\nname = \"a\"\n", "neither logs nor boards"),
            ("[[airframe]]\nname = \"a\"\nlogs = [\"[\"]\n", "logs: `[`"),
            ("[[airframe]]\nname = \"a\"\nserial = 3\n", "unknown field"),
            (
                "[[airframe]]\nname = \" \"\nlogs = [\"x\"]\n",
                "name is empty",
            ),
        ] {
            let e = Airframes::parse(text, "t.toml").unwrap_err().to_string();
            assert!(e.contains(why), "{text:?}: {e}");
        }
    }
}
