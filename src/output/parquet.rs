//! `ahcmon scan --parquet`: the same rows as the JSON lines, as one Parquet table for pandas,
//! pyarrow, DuckDB or Spark.
//!
//! The rows' nested objects are flattened (`mit_ukf.gamma_lo` → `mit_ukf_gamma_lo`) so that
//! every column is a plain typed value; [`COLUMNS`] is the schema, in column order, and the
//! table in `docs/fleet.md` states it. Every column is nullable except those every row has
//! (the log and the vehicle); a JSON `null` or a key a row lacks (a vehicle never estimated
//! has no actuator) is a null. Snappy-compressed, in row groups of [`ROW_GROUP`] rows.

use parquet::basic::Compression;
use parquet::data_type::{ByteArray, ByteArrayType, DoubleType, Int32Type, Int64Type};
use parquet::file::properties::WriterProperties;
use parquet::file::writer::SerializedFileWriter;
use parquet::schema::parser::parse_message_type;
use serde_json::Value;
use std::sync::Arc;

/// Rows per row group: a reader's unit of work and of memory.
pub const ROW_GROUP: usize = 65_536;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Text,
    Int32,
    Int64,
    Double,
}

/// A column: its name, where its value sits in a row (`/`-separated keys), its type, and
/// whether every row must have it.
#[derive(Debug, Clone, Copy)]
pub struct Column {
    pub name: &'static str,
    pub path: &'static str,
    pub kind: Kind,
    pub required: bool,
}

const fn col(name: &'static str, path: &'static str, kind: Kind, required: bool) -> Column {
    Column {
        name,
        path,
        kind,
        required,
    }
}

macro_rules! filter_columns {
    ($f:literal) => {
        [
            col(
                concat!($f, "_gamma"),
                concat!($f, "/gamma"),
                Kind::Double,
                false,
            ),
            col(
                concat!($f, "_gamma_lo"),
                concat!($f, "/gamma_lo"),
                Kind::Double,
                false,
            ),
            col(
                concat!($f, "_gamma_hi"),
                concat!($f, "/gamma_hi"),
                Kind::Double,
                false,
            ),
            col(
                concat!($f, "_delta"),
                concat!($f, "/delta"),
                Kind::Double,
                false,
            ),
            col(
                concat!($f, "_delta_lo"),
                concat!($f, "/delta_lo"),
                Kind::Double,
                false,
            ),
            col(
                concat!($f, "_delta_hi"),
                concat!($f, "/delta_hi"),
                Kind::Double,
                false,
            ),
            col(
                concat!($f, "_gamma_steps"),
                concat!($f, "/gamma_steps"),
                Kind::Int64,
                false,
            ),
            col(
                concat!($f, "_delta_steps"),
                concat!($f, "/delta_steps"),
                Kind::Int64,
                false,
            ),
        ]
    };
}

const LOG_COLUMNS: [Column; 19] = [
    col("file", "file", Kind::Text, true),
    col("format", "format", Kind::Text, true),
    col("airframe", "airframe", Kind::Text, false),
    col("board_uid", "board_uid", Kind::Text, false),
    col("sysid", "sysid", Kind::Int32, true),
    col("vehicle_type", "vehicle_type", Kind::Text, false),
    col("profile", "profile", Kind::Text, false),
    col("start_unix_us", "start_unix_us", Kind::Int64, false),
    col("log_dropped", "log_dropped", Kind::Int64, true),
    col("estimated_s", "estimated_s", Kind::Double, false),
    col("samples", "samples", Kind::Int64, true),
    col("frames_missing", "frames_missing", Kind::Int64, true),
    col("stage", "stage", Kind::Text, false),
    col("no_estimates", "no_estimates", Kind::Text, false),
    col("actuator", "actuator", Kind::Text, false),
    col("channel", "channel", Kind::Int32, false),
    col("faults", "faults", Kind::Int64, false),
    col("first_fault_t", "first_fault_t", Kind::Double, false),
    col("state", "state", Kind::Text, false),
];

/// The table's schema, in column order.
pub const COLUMNS: [Column; 35] = {
    let ukf = filter_columns!("mit_ukf");
    let set = filter_columns!("set");
    let mut all = [LOG_COLUMNS[0]; 35];
    let mut i = 0;
    while i < 19 {
        all[i] = LOG_COLUMNS[i];
        i += 1;
    }
    while i < 27 {
        all[i] = ukf[i - 19];
        i += 1;
    }
    while i < 35 {
        all[i] = set[i - 27];
        i += 1;
    }
    all
};

#[derive(Debug, thiserror::Error)]
pub enum ParquetError {
    #[error("row {row}: {column} is missing, and every row must have it")]
    Missing { row: usize, column: &'static str },
    #[error("row {row}: {column} is {value}, not {kind:?}")]
    WrongType {
        row: usize,
        column: &'static str,
        value: String,
        kind: Kind,
    },
    #[error("writing Parquet: {0}")]
    Write(#[from] parquet::errors::ParquetError),
}

/// The Parquet message type of [`COLUMNS`].
pub fn schema() -> String {
    let mut s = String::from("message ahcmon_scan_row {\n");
    for c in COLUMNS {
        let repetition = if c.required { "REQUIRED" } else { "OPTIONAL" };
        let physical = match c.kind {
            Kind::Text => "BYTE_ARRAY",
            Kind::Int32 => "INT32",
            Kind::Int64 => "INT64",
            Kind::Double => "DOUBLE",
        };
        let logical = if c.kind == Kind::Text {
            " (STRING)"
        } else {
            ""
        };
        s.push_str(&format!("  {repetition} {physical} {}{logical};\n", c.name));
    }
    s.push('}');
    s
}

fn lookup<'a>(row: &'a Value, path: &str) -> Option<&'a Value> {
    path.split('/')
        .try_fold(row, |v, key| v.get(key))
        .filter(|v| !v.is_null())
}

/// One column's values (nulls left out) and definition levels (1 present, 0 null).
struct Chunk<T> {
    values: Vec<T>,
    defined: Vec<i16>,
}

fn chunk<T>(
    rows: &[Value],
    first_row: usize,
    c: Column,
    read: impl Fn(&Value) -> Option<T>,
) -> Result<Chunk<T>, ParquetError> {
    let mut out = Chunk {
        values: Vec::with_capacity(rows.len()),
        defined: Vec::with_capacity(rows.len()),
    };
    for (k, row) in rows.iter().enumerate() {
        match lookup(row, c.path) {
            None if c.required => {
                return Err(ParquetError::Missing {
                    row: first_row + k,
                    column: c.name,
                });
            }
            None => out.defined.push(0),
            Some(v) => {
                let x = read(v).ok_or_else(|| ParquetError::WrongType {
                    row: first_row + k,
                    column: c.name,
                    value: v.to_string(),
                    kind: c.kind,
                })?;
                out.values.push(x);
                out.defined.push(1);
            }
        }
    }
    Ok(out)
}

/// The rows as a Parquet file's bytes. Checks every value against its column first: a row
/// that does not fit is an error naming the row and column, and nothing is returned.
pub fn to_parquet(rows: &[Value]) -> Result<Vec<u8>, ParquetError> {
    let schema = Arc::new(parse_message_type(&schema())?);
    let props = Arc::new(
        WriterProperties::builder()
            .set_compression(Compression::SNAPPY)
            .set_created_by(format!("ahcmon {}", env!("CARGO_PKG_VERSION")))
            .build(),
    );
    let mut out = Vec::new();
    let mut writer = SerializedFileWriter::new(&mut out, schema, props)?;
    for (g, group) in rows.chunks(ROW_GROUP).enumerate() {
        let first_row = g * ROW_GROUP;
        let mut row_group = writer.next_row_group()?;
        for c in COLUMNS {
            let Some(mut column) = row_group.next_column()? else {
                unreachable!("the schema has a column per entry of COLUMNS");
            };
            let levels = |d: &[i16]| (!c.required).then_some(d).map(<[i16]>::to_vec);
            match c.kind {
                Kind::Text => {
                    let k = chunk(group, first_row, c, |v| {
                        v.as_str().map(|s| ByteArray::from(s.as_bytes().to_vec()))
                    })?;
                    let d = levels(&k.defined);
                    column
                        .typed::<ByteArrayType>()
                        .write_batch(&k.values, d.as_deref(), None)?;
                }
                Kind::Int32 => {
                    let k = chunk(group, first_row, c, |v| {
                        v.as_i64().and_then(|x| i32::try_from(x).ok())
                    })?;
                    let d = levels(&k.defined);
                    column
                        .typed::<Int32Type>()
                        .write_batch(&k.values, d.as_deref(), None)?;
                }
                Kind::Int64 => {
                    let k = chunk(group, first_row, c, |v| {
                        v.as_i64()
                            .or_else(|| v.as_u64().and_then(|x| i64::try_from(x).ok()))
                    })?;
                    let d = levels(&k.defined);
                    column
                        .typed::<Int64Type>()
                        .write_batch(&k.values, d.as_deref(), None)?;
                }
                Kind::Double => {
                    let k = chunk(group, first_row, c, Value::as_f64)?;
                    let d = levels(&k.defined);
                    column
                        .typed::<DoubleType>()
                        .write_batch(&k.values, d.as_deref(), None)?;
                }
            }
            column.close()?;
        }
        row_group.close()?;
    }
    writer.close()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn the_schema_names_each_column_once_in_order() {
        let names: Vec<&str> = COLUMNS.iter().map(|c| c.name).collect();
        let mut unique = names.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), names.len(), "{names:?}");
        assert_eq!(names[18], "state");
        assert_eq!(names[19], "mit_ukf_gamma");
        assert_eq!(names[34], "set_delta_steps");
        assert!(parse_message_type(&schema()).is_ok(), "{}", schema());
    }

    #[test]
    fn a_row_missing_a_required_column_or_of_the_wrong_type_is_refused() {
        let row = json!({"file": "a.tlog", "format": "x", "sysid": 1, "log_dropped": 0,
            "samples": 10, "frames_missing": 0});
        assert!(to_parquet(std::slice::from_ref(&row)).is_ok());
        let mut missing = row.clone();
        missing.as_object_mut().unwrap().remove("samples");
        assert!(matches!(
            to_parquet(&[row.clone(), missing]),
            Err(ParquetError::Missing {
                row: 1,
                column: "samples"
            })
        ));
        let mut wrong = row.clone();
        wrong["mit_ukf"] = json!({"gamma": "high"});
        assert!(matches!(
            to_parquet(&[wrong]),
            Err(ParquetError::WrongType {
                column: "mit_ukf_gamma",
                ..
            })
        ));
    }

    /// Read back with the crate's own reader: every value where it was put, nulls as nulls.
    #[test]
    fn values_and_nulls_read_back() {
        use parquet::file::reader::{FileReader, SerializedFileReader};
        use parquet::record::Field;
        let rows = vec![
            json!({"file": "a.tlog", "format": "x", "sysid": 3, "log_dropped": 2,
                "samples": 10, "frames_missing": 1, "actuator": "motor1",
                "mit_ukf": {"gamma": 0.95, "gamma_steps": 7}}),
            json!({"file": "b.tlog", "format": "x", "sysid": 4, "log_dropped": 0,
                "samples": 0, "frames_missing": 0, "no_estimates": "why"}),
        ];
        let path =
            std::env::temp_dir().join(format!("ahcmon-parquet-{}.parquet", std::process::id()));
        std::fs::write(&path, to_parquet(&rows).unwrap()).unwrap();
        let reader = SerializedFileReader::new(std::fs::File::open(&path).unwrap()).unwrap();
        assert_eq!(reader.metadata().file_metadata().num_rows(), 2);
        let got: Vec<std::collections::HashMap<String, Field>> = reader
            .get_row_iter(None)
            .unwrap()
            .map(|r| {
                r.unwrap()
                    .get_column_iter()
                    .map(|(k, v)| (k.clone(), v.clone()))
                    .collect()
            })
            .collect();
        let _ = std::fs::remove_file(&path);
        assert_eq!(got[0]["sysid"], Field::Int(3));
        assert_eq!(got[0]["actuator"], Field::Str("motor1".into()));
        assert_eq!(got[0]["mit_ukf_gamma"], Field::Double(0.95));
        assert_eq!(got[0]["mit_ukf_gamma_steps"], Field::Long(7));
        assert_eq!(got[0]["mit_ukf_delta"], Field::Null);
        assert_eq!(got[1]["actuator"], Field::Null);
        assert_eq!(got[1]["no_estimates"], Field::Str("why".into()));
    }
}
