//! Training and checking data: a validated table of input rows and targets, read from
//! CSV or JSON.

use std::path::Path;
use std::str::FromStr;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::AnfisError;

/// How a data file is encoded.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DataFormat {
    /// From the file extension: `.csv` or `.json` (any case).
    #[default]
    Auto,
    /// Comma-separated values with a header row of column names.
    Csv,
    /// An array of objects, or `{"inputs": [[...]], "targets": [...]}`.
    Json,
}

impl DataFormat {
    /// Resolves [`DataFormat::Auto`] from the path's extension.
    pub fn resolve(self, path: &Path) -> Result<DataFormat, AnfisError> {
        match self {
            DataFormat::Auto => {
                let ext = path
                    .extension()
                    .and_then(|e| e.to_str())
                    .map(str::to_ascii_lowercase);
                match ext.as_deref() {
                    Some("csv") => Ok(DataFormat::Csv),
                    Some("json") => Ok(DataFormat::Json),
                    _ => Err(AnfisError::UnknownFormat {
                        path: path.to_path_buf(),
                    }),
                }
            }
            other => Ok(other),
        }
    }
}

impl FromStr for DataFormat {
    type Err = AnfisError;

    /// `auto`, `csv` or `json` (any case).
    fn from_str(s: &str) -> Result<Self, AnfisError> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Ok(DataFormat::Auto),
            "csv" => Ok(DataFormat::Csv),
            "json" => Ok(DataFormat::Json),
            _ => Err(AnfisError::InvalidConfig {
                field: "format".into(),
                reason: format!("unknown data format '{s}' (auto, csv or json)"),
            }),
        }
    }
}

/// A validated data set: at least one row, at least one input, every value finite,
/// unique non-empty column names.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    input_names: Vec<String>,
    target_name: String,
    /// Row-major, `input_names.len()` values per row.
    inputs: Vec<f64>,
    targets: Vec<f64>,
}

fn bad(reason: impl Into<String>) -> AnfisError {
    AnfisError::InvalidData {
        reason: reason.into(),
    }
}

fn check_names(input_names: &[String], target_name: &str) -> Result<(), AnfisError> {
    if input_names.is_empty() {
        return Err(bad("at least one input column is required"));
    }
    for (i, name) in input_names.iter().enumerate() {
        if name.is_empty() {
            return Err(bad(format!("input {i} has an empty name")));
        }
        if input_names[..i].contains(name) {
            return Err(bad(format!("input column '{name}' is named twice")));
        }
        if name == target_name {
            return Err(bad(format!(
                "column '{name}' is both an input and the target"
            )));
        }
    }
    if target_name.is_empty() {
        return Err(bad("the target has an empty name"));
    }
    Ok(())
}

impl Dataset {
    /// Builds a data set from rows of inputs and their targets.
    pub fn new(
        input_names: Vec<String>,
        target_name: String,
        rows: Vec<Vec<f64>>,
        targets: Vec<f64>,
    ) -> Result<Self, AnfisError> {
        check_names(&input_names, &target_name)?;
        if rows.is_empty() {
            return Err(bad("no data rows"));
        }
        if rows.len() != targets.len() {
            return Err(bad(format!(
                "{} input rows but {} targets",
                rows.len(),
                targets.len()
            )));
        }
        let n = input_names.len();
        let mut inputs = Vec::with_capacity(rows.len() * n);
        for (k, row) in rows.iter().enumerate() {
            if row.len() != n {
                return Err(bad(format!(
                    "row {k} has {} inputs, expected {n} ({})",
                    row.len(),
                    input_names.join(", ")
                )));
            }
            for (value, name) in row.iter().zip(&input_names) {
                if !value.is_finite() {
                    return Err(bad(format!(
                        "row {k}, column '{name}': not a finite number ({value})"
                    )));
                }
            }
            inputs.extend_from_slice(row);
        }
        for (k, t) in targets.iter().enumerate() {
            if !t.is_finite() {
                return Err(bad(format!(
                    "row {k}, column '{target_name}': not a finite number ({t})"
                )));
            }
        }
        Ok(Dataset {
            input_names,
            target_name,
            inputs,
            targets,
        })
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.targets.len()
    }

    /// Always false for a validated data set (kept for the `len` convention).
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }

    /// Number of inputs per row.
    pub fn n_inputs(&self) -> usize {
        self.input_names.len()
    }

    /// Input column names.
    pub fn input_names(&self) -> &[String] {
        &self.input_names
    }

    /// Target column name.
    pub fn target_name(&self) -> &str {
        &self.target_name
    }

    /// The input rows.
    pub fn rows(&self) -> std::slice::ChunksExact<'_, f64> {
        self.inputs.chunks_exact(self.input_names.len())
    }

    /// The targets, one per row.
    pub fn targets(&self) -> &[f64] {
        &self.targets
    }

    /// [min, max] of every input over the rows.
    pub fn input_ranges(&self) -> Vec<[f64; 2]> {
        let mut ranges = vec![[f64::INFINITY, f64::NEG_INFINITY]; self.n_inputs()];
        for row in self.rows() {
            for (r, &v) in ranges.iter_mut().zip(row) {
                r[0] = r[0].min(v);
                r[1] = r[1].max(v);
            }
        }
        ranges
    }

    /// Reads a data file. `inputs` and `target` name the columns (see
    /// [`Dataset::from_csv_str`] and [`Dataset::from_json_str`]); errors name the file.
    pub fn load<S: AsRef<str>>(
        path: &Path,
        format: DataFormat,
        inputs: &[S],
        target: &str,
    ) -> Result<Self, AnfisError> {
        let format = format.resolve(path)?;
        let text = std::fs::read_to_string(path).map_err(|source| AnfisError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let parsed = match format {
            DataFormat::Csv | DataFormat::Auto => Dataset::from_csv_str(&text, inputs, target),
            DataFormat::Json => Dataset::from_json_str(&text, inputs, target),
        };
        parsed.map_err(|e| AnfisError::in_file(path, e))
    }

    /// Parses CSV: the first line that is neither blank nor a `#` comment is the header
    /// of column names; then one row per line (blank and `#` lines skipped), every line
    /// with the header's number of fields. Fields are trimmed and may be wrapped in
    /// double quotes (no quoted commas). `inputs` selects the input columns by name,
    /// in that order (empty: every column except the target); `target` names the target.
    /// Columns not selected are not parsed, so they may hold text. Errors name the
    /// 1-based line and the column.
    pub fn from_csv_str<S: AsRef<str>>(
        text: &str,
        inputs: &[S],
        target: &str,
    ) -> Result<Self, AnfisError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(k, l)| (k + 1, l))
            .filter(|(_, l)| {
                let t = l.trim();
                !t.is_empty() && !t.starts_with('#')
            });
        let Some((header_line, header)) = lines.next() else {
            return Err(bad("empty CSV: no header row"));
        };
        let columns: Vec<String> = header.split(',').map(|f| clean(f).to_string()).collect();
        for (k, name) in columns.iter().enumerate() {
            if columns[..k].contains(name) {
                return Err(AnfisError::Csv {
                    line: header_line,
                    column: name.clone(),
                    reason: "duplicate column name in the header".into(),
                });
            }
        }
        let find = |name: &str| {
            columns
                .iter()
                .position(|c| c == name)
                .ok_or_else(|| AnfisError::MissingColumn {
                    name: name.to_string(),
                    available: columns.join(", "),
                })
        };
        let target_index = find(target)?;
        let input_indices: Vec<usize> = if inputs.is_empty() {
            (0..columns.len()).filter(|&k| k != target_index).collect()
        } else {
            inputs
                .iter()
                .map(|n| find(n.as_ref()))
                .collect::<Result<_, _>>()?
        };
        let input_names: Vec<String> = input_indices.iter().map(|&k| columns[k].clone()).collect();
        check_names(&input_names, target)?;

        let mut rows = Vec::new();
        let mut targets = Vec::new();
        for (line, text) in lines {
            let fields: Vec<&str> = text.split(',').collect();
            if fields.len() != columns.len() {
                return Err(AnfisError::Csv {
                    line,
                    column: columns.get(fields.len()).cloned().unwrap_or_default(),
                    reason: format!(
                        "{} fields, the header (line {header_line}) has {}",
                        fields.len(),
                        columns.len()
                    ),
                });
            }
            let number = |k: usize| -> Result<f64, AnfisError> {
                let raw = clean(fields[k]);
                let csv_err = |reason: String| AnfisError::Csv {
                    line,
                    column: columns[k].clone(),
                    reason,
                };
                let v: f64 = raw
                    .parse()
                    .map_err(|_| csv_err(format!("'{raw}' is not a number")))?;
                if v.is_finite() {
                    Ok(v)
                } else {
                    Err(csv_err(format!("'{raw}' is not a finite number")))
                }
            };
            rows.push(
                input_indices
                    .iter()
                    .map(|&k| number(k))
                    .collect::<Result<Vec<_>, _>>()?,
            );
            targets.push(number(target_index)?);
        }
        if rows.is_empty() {
            return Err(bad(format!(
                "the CSV has a header (line {header_line}) but no data rows"
            )));
        }
        Dataset::new(input_names, target.to_string(), rows, targets)
    }

    /// Parses JSON in one of two layouts:
    ///
    /// * an array of objects, `[{"x": 1.0, "y": 2.0, "z": 0.5}, ...]`: `inputs` (not
    ///   empty) and `target` name the fields; other fields are ignored;
    /// * `{"inputs": [[1.0, 2.0], ...], "targets": [0.5, ...]}` with optional
    ///   `"input_names"` and `"target_name"`: with names in the file, `inputs` selects
    ///   columns by name (empty: all); without, `inputs` labels the columns in order
    ///   (empty: `x1`, `x2`, ...); `target` (empty: the file's or `y`) must match the
    ///   file's `target_name` when both are given.
    pub fn from_json_str<S: AsRef<str>>(
        text: &str,
        inputs: &[S],
        target: &str,
    ) -> Result<Self, AnfisError> {
        let value: Value = serde_json::from_str(text).map_err(|source| AnfisError::Json {
            what: "data".into(),
            source,
        })?;
        let inputs: Vec<String> = inputs.iter().map(|s| s.as_ref().to_string()).collect();
        match value {
            Value::Array(items) => json_objects(&items, inputs, target),
            Value::Object(map) => json_matrix(&map, inputs, target),
            _ => Err(AnfisError::JsonData {
                location: "document".into(),
                reason: "expected an array of objects or {\"inputs\": [[...]], \"targets\": [...]}"
                    .into(),
            }),
        }
    }
}

/// A CSV field without surrounding whitespace and double quotes.
fn clean(field: &str) -> &str {
    let t = field.trim();
    t.strip_prefix('"')
        .and_then(|s| s.strip_suffix('"'))
        .unwrap_or(t)
        .trim()
}

fn json_number(value: Option<&Value>, location: impl Fn() -> String) -> Result<f64, AnfisError> {
    let err = |reason: &str| AnfisError::JsonData {
        location: location(),
        reason: reason.into(),
    };
    match value {
        None => Err(err("missing")),
        Some(v) => v
            .as_f64()
            .ok_or_else(|| err(&format!("not a number ({v})"))),
    }
}

fn json_objects(items: &[Value], inputs: Vec<String>, target: &str) -> Result<Dataset, AnfisError> {
    if inputs.is_empty() {
        return Err(bad(
            "an array of JSON objects has no column order: name the input fields",
        ));
    }
    check_names(&inputs, target)?;
    let mut rows = Vec::with_capacity(items.len());
    let mut targets = Vec::with_capacity(items.len());
    for (k, item) in items.iter().enumerate() {
        let Value::Object(obj) = item else {
            return Err(AnfisError::JsonData {
                location: format!("[{k}]"),
                reason: format!("expected an object, got {item}"),
            });
        };
        rows.push(
            inputs
                .iter()
                .map(|name| json_number(obj.get(name), || format!("[{k}].{name}")))
                .collect::<Result<Vec<_>, _>>()?,
        );
        targets.push(json_number(obj.get(target), || format!("[{k}].{target}"))?);
    }
    Dataset::new(inputs, target.to_string(), rows, targets)
}

/// `{"inputs": [[...]], "targets": [...]}`, optionally with `input_names` and
/// `target_name`: the columns `inputs` names (all of them when empty), the target
/// `target` (the file's `target_name`, or `y`, when empty).
fn json_matrix(
    map: &serde_json::Map<String, Value>,
    inputs: Vec<String>,
    target: &str,
) -> Result<Dataset, AnfisError> {
    const KEYS: [&str; 4] = ["inputs", "targets", "input_names", "target_name"];
    if let Some(key) = map.keys().find(|k| !KEYS.contains(&k.as_str())) {
        return Err(AnfisError::JsonData {
            location: key.clone(),
            reason: format!("unknown field (expected {})", KEYS.join(", ")),
        });
    }
    let Some(Value::Array(rows_json)) = map.get("inputs") else {
        return Err(field_err(
            "inputs",
            "missing or not an array of rows".into(),
        ));
    };
    let Some(Value::Array(targets_json)) = map.get("targets") else {
        return Err(field_err(
            "targets",
            "missing or not an array of numbers".into(),
        ));
    };
    let file_names = json_input_names(map)?;
    let target_name = json_target_name(map, target)?;
    let (matrix, width) = json_input_rows(rows_json, file_names.as_deref())?;
    let targets = targets_json
        .iter()
        .enumerate()
        .map(|(k, v)| json_number(Some(v), || format!("targets[{k}]")))
        .collect::<Result<Vec<_>, _>>()?;
    let (names, selection) = select_columns(file_names, inputs, width)?;
    let rows = matrix
        .into_iter()
        .map(|r| selection.iter().map(|&j| r[j]).collect())
        .collect();
    Dataset::new(names, target_name, rows, targets)
}

/// An error at `location` in JSON data.
fn field_err(location: &str, reason: String) -> AnfisError {
    AnfisError::JsonData {
        location: location.into(),
        reason,
    }
}

/// The file's `input_names`, when given.
fn json_input_names(
    map: &serde_json::Map<String, Value>,
) -> Result<Option<Vec<String>>, AnfisError> {
    Ok(match map.get("input_names") {
        None => None,
        Some(Value::Array(names)) => Some(
            names
                .iter()
                .enumerate()
                .map(|(k, n)| {
                    n.as_str().map(str::to_string).ok_or_else(|| {
                        field_err(&format!("input_names[{k}]"), format!("not a string ({n})"))
                    })
                })
                .collect::<Result<_, _>>()?,
        ),
        Some(other) => {
            return Err(field_err(
                "input_names",
                format!("not an array of strings ({other})"),
            ));
        }
    })
}

/// The target's name: `target` (which the file's `target_name`, when given, must
/// match), or when empty the file's `target_name`, or `y`.
fn json_target_name(
    map: &serde_json::Map<String, Value>,
    target: &str,
) -> Result<String, AnfisError> {
    let file_target = match map.get("target_name") {
        None => None,
        Some(Value::String(s)) => Some(s.clone()),
        Some(other) => return Err(field_err("target_name", format!("not a string ({other})"))),
    };
    Ok(match (&file_target, target.is_empty()) {
        (Some(ft), false) if ft != target => {
            return Err(AnfisError::MissingColumn {
                name: target.to_string(),
                available: format!("target_name \"{ft}\""),
            });
        }
        (_, false) => target.to_string(),
        (Some(ft), true) => ft.clone(),
        (None, true) => "y".to_string(),
    })
}

/// The rows of `inputs`, each a number for every input column (as many as the file's
/// `input_names`, or the first row's length), and that width.
fn json_input_rows(
    rows_json: &[Value],
    file_names: Option<&[String]>,
) -> Result<(Vec<Vec<f64>>, usize), AnfisError> {
    let mut matrix = Vec::with_capacity(rows_json.len());
    for (k, row) in rows_json.iter().enumerate() {
        let Value::Array(values) = row else {
            return Err(field_err(
                &format!("inputs[{k}]"),
                format!("not an array ({row})"),
            ));
        };
        matrix.push(
            values
                .iter()
                .enumerate()
                .map(|(j, v)| json_number(Some(v), || format!("inputs[{k}][{j}]")))
                .collect::<Result<Vec<_>, _>>()?,
        );
    }
    let width = match file_names {
        Some(names) => names.len(),
        None => matrix.first().map_or(0, Vec::len),
    };
    if let Some((k, row)) = matrix.iter().enumerate().find(|(_, r)| r.len() != width) {
        return Err(field_err(
            &format!("inputs[{k}]"),
            format!("has {} values, expected {width}", row.len()),
        ));
    }
    Ok((matrix, width))
}

/// The model's input names and the column of each among the `width` in the file:
/// `inputs` picked by the file's names, or all columns in order (named by the file,
/// by `inputs`, or x1, x2, ...).
fn select_columns(
    file_names: Option<Vec<String>>,
    inputs: Vec<String>,
    width: usize,
) -> Result<(Vec<String>, Vec<usize>), AnfisError> {
    Ok(match (file_names, inputs.is_empty()) {
        (Some(names), true) => (names, (0..width).collect()),
        (Some(names), false) => {
            let selection = inputs
                .iter()
                .map(|n| {
                    names
                        .iter()
                        .position(|c| c == n)
                        .ok_or_else(|| AnfisError::MissingColumn {
                            name: n.clone(),
                            available: names.join(", "),
                        })
                })
                .collect::<Result<Vec<_>, _>>()?;
            (inputs, selection)
        }
        (None, true) => (
            (1..=width).map(|k| format!("x{k}")).collect(),
            (0..width).collect(),
        ),
        (None, false) => {
            if inputs.len() != width {
                return Err(bad(format!(
                    "{} input names given for {width} unnamed input columns",
                    inputs.len()
                )));
            }
            (inputs, (0..width).collect())
        }
    })
}
