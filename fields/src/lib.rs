//! One toolkit for the fields of TOML files (scenarios, bench files, the controller's
//! configuration): a [`FieldPath`] names a field exactly (`obstacles[1].motion.speed`,
//! `gps.rtk.horizontal_sigma_m`), a [`FieldError`] says what is wrong with it, and
//! [`FieldError::located`] finds the line it is on in the file's text, so every
//! refusal reads `file:line: field: message`.
//!
//! The checks ([`finite`], [`positive`], [`within`], ...) are the range checks every
//! loader shares. Coordinates and sizes also have to survive the narrowing to `f32`
//! that physics and wire formats do, so [`PLAUSIBLE_COORDINATE`] bounds positions. A
//! physical parameter has a [`Range`] that names its source, and a loader's table of
//! them ([`Bound`] rows) is checked with [`check_bounds`].
//!
//! [`read_file`] and [`parse_toml`] read such a file, with a [`FileError`] that names
//! it whatever went wrong.

use std::borrow::Cow;
use std::fmt;

/// Positions, in metres from the origin, that a run may use: 100 km is far more than
/// any course, and small enough that `f32` still resolves centimetres (beyond about
/// 1e5 m the physics' single precision no longer does, and beyond 3.4e38 values turn
/// into infinities that collide with everything).
pub const PLAUSIBLE_COORDINATE: f64 = 100_000.0;

/// One step of a field path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Segment {
    Key(Cow<'static, str>),
    Index(usize),
}

/// Where a field is: keys and array indices from the top of the file.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FieldPath(Vec<Segment>);

impl FieldPath {
    /// The top of the file.
    pub fn root() -> FieldPath {
        FieldPath(Vec::new())
    }

    /// A path of keys (`FieldPath::of(&["gps", "rtk"])`).
    pub fn of(keys: &[&'static str]) -> FieldPath {
        FieldPath(
            keys.iter()
                .map(|k| Segment::Key(Cow::Borrowed(*k)))
                .collect(),
        )
    }

    /// This path, then the key `k`.
    pub fn key(&self, k: impl Into<Cow<'static, str>>) -> FieldPath {
        let mut p = self.clone();
        p.0.push(Segment::Key(k.into()));
        p
    }

    /// This path, then element `i`.
    pub fn index(&self, i: usize) -> FieldPath {
        let mut p = self.clone();
        p.0.push(Segment::Index(i));
        p
    }

    /// `prefix` followed by this path (a section's error placed in the whole file).
    pub fn under(&self, prefix: &FieldPath) -> FieldPath {
        let mut p = prefix.clone();
        p.0.extend(self.0.iter().cloned());
        p
    }

    pub fn segments(&self) -> &[Segment] {
        &self.0
    }

    /// The 1-based line of this field in the TOML `text`: the field's own line when
    /// the file sets it, else the line of its nearest ancestor that the file has (a
    /// field left to its default is refused at the table that would hold it), 1 when
    /// the text does not parse.
    pub fn line_in(&self, text: &str) -> usize {
        let Ok(root) = toml::de::DeTable::parse(text) else {
            return 1;
        };
        let mut span = root.span();
        let mut value: Option<&toml::de::DeValue<'_>> = None;
        let mut table = Some(root.get_ref());
        for part in &self.0 {
            let next = match (part, table, value) {
                (Segment::Key(k), Some(t), _) => t
                    .iter()
                    .find(|(key, _)| key.get_ref().as_ref() == k.as_ref())
                    .map(|(_, v)| v),
                (Segment::Index(i), _, Some(toml::de::DeValue::Array(items))) => items.get(*i),
                _ => None,
            };
            let Some(next) = next else { break };
            span = next.span();
            value = Some(next.get_ref());
            table = match next.get_ref() {
                toml::de::DeValue::Table(t) => Some(t),
                _ => None,
            };
        }
        text[..span.start.min(text.len())].matches('\n').count() + 1
    }
}

impl fmt::Display for FieldPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut first = true;
        for s in &self.0 {
            match s {
                Segment::Key(k) => {
                    if !first {
                        f.write_str(".")?;
                    }
                    f.write_str(k)?;
                }
                Segment::Index(i) => write!(f, "[{i}]")?,
            }
            first = false;
        }
        if first {
            f.write_str("(the file)")?;
        }
        Ok(())
    }
}

/// Why a TOML file was refused: it could not be read, it is not the TOML its type
/// reads, or a value in it makes no sense.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    /// The system's reason is in the message (not a source as well: a printer of
    /// error chains would say it twice).
    #[error("{file}: {cause}")]
    Read { file: String, cause: std::io::Error },
    /// Syntax errors and unknown or mistyped fields (the TOML error names line and
    /// column).
    #[error("{file}: {message}")]
    Parse { file: String, message: String },
    /// A well-formed value that makes no sense, with the file and line it is on.
    #[error(transparent)]
    Invalid(#[from] LocatedError),
}

/// The text of the file at `path`.
pub fn read_file(path: &std::path::Path) -> Result<String, FileError> {
    std::fs::read_to_string(path).map_err(|cause| FileError::Read {
        file: path.display().to_string(),
        cause,
    })
}

/// TOML `text` of `file` as a `T`.
pub fn parse_toml<T: serde::de::DeserializeOwned>(text: &str, file: &str) -> Result<T, FileError> {
    toml::from_str(text).map_err(|e| FileError::Parse {
        file: file.to_owned(),
        message: e.to_string().trim_end().to_owned(),
    })
}

/// A field that makes no sense, and why.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{path}: {message}")]
pub struct FieldError {
    pub path: FieldPath,
    pub message: String,
}

impl FieldError {
    pub fn new(path: FieldPath, message: impl Into<String>) -> FieldError {
        FieldError {
            path,
            message: message.into(),
        }
    }

    /// The same error for a section that sits at `prefix` in the file.
    pub fn under(self, prefix: &FieldPath) -> FieldError {
        FieldError {
            path: self.path.under(prefix),
            message: self.message,
        }
    }

    /// This error placed in the file `file` whose text is `text`.
    pub fn located(self, text: &str, file: &str) -> LocatedError {
        LocatedError {
            file: file.to_owned(),
            line: self.path.line_in(text),
            field: self.path.to_string(),
            message: self.message,
        }
    }
}

/// A field error with the file and line it is on.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{file}:{line}: {field}: {message}")]
pub struct LocatedError {
    pub file: String,
    pub line: usize,
    pub field: String,
    pub message: String,
}

/// `v` is a finite number.
pub fn finite(path: &FieldPath, v: f64) -> Result<(), FieldError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(FieldError::new(
            path.clone(),
            format!("{v} is not a finite number"),
        ))
    }
}

/// `v` is finite and above zero.
pub fn positive(path: &FieldPath, v: f64) -> Result<(), FieldError> {
    finite(path, v)?;
    if v > 0.0 {
        Ok(())
    } else {
        Err(FieldError::new(
            path.clone(),
            format!("must be positive, is {v}"),
        ))
    }
}

/// `v` is finite and not below zero.
pub fn non_negative(path: &FieldPath, v: f64) -> Result<(), FieldError> {
    finite(path, v)?;
    if v >= 0.0 {
        Ok(())
    } else {
        Err(FieldError::new(
            path.clone(),
            format!("must not be negative, is {v}"),
        ))
    }
}

/// `v` is finite and within `[lo, hi]`; `unit` follows the bounds in the message.
pub fn within(path: &FieldPath, v: f64, lo: f64, hi: f64, unit: &str) -> Result<(), FieldError> {
    finite(path, v)?;
    if (lo..=hi).contains(&v) {
        Ok(())
    } else {
        Err(FieldError::new(
            path.clone(),
            outside(lo, hi, unit, &v.to_string()),
        ))
    }
}

/// "must be within [lo, hi] unit, is v".
fn outside(lo: f64, hi: f64, unit: &str, v: &str) -> String {
    let unit = if unit.is_empty() {
        String::new()
    } else {
        format!(" {unit}")
    };
    format!("must be within [{lo}, {hi}]{unit}, is {v}")
}

/// `v` is finite, above zero and at most `hi`.
pub fn positive_up_to(path: &FieldPath, v: f64, hi: f64, unit: &str) -> Result<(), FieldError> {
    positive(path, v)?;
    within(path, v, 0.0, hi, unit)
}

/// A position coordinate, metres: finite and within ±[`PLAUSIBLE_COORDINATE`].
pub fn coordinate(path: &FieldPath, v: f64) -> Result<(), FieldError> {
    within(
        path,
        v,
        -PLAUSIBLE_COORDINATE,
        PLAUSIBLE_COORDINATE,
        "m from the origin",
    )
}

/// An angle in degrees: finite and within ±360.
pub fn angle_deg(path: &FieldPath, v: f64) -> Result<(), FieldError> {
    within(path, v, -360.0, 360.0, "degrees")
}

/// The plausible range of a physical quantity: its bounds, its unit, and where the
/// bounds come from (a datasheet, the DBC, the golf car), which a refusal quotes. A
/// range is generous (other Ackermann carts, other scanners fit) but closed: a
/// wheelbase of 1e-9 m or 1e300 m is no vehicle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    pub lo: f64,
    pub hi: f64,
    pub unit: &'static str,
    /// Where the bounds come from.
    pub source: &'static str,
}

impl Range {
    pub const fn new(lo: f64, hi: f64, unit: &'static str, source: &'static str) -> Range {
        Range {
            lo,
            hi,
            unit,
            source,
        }
    }

    /// `v` is finite and within the range; the refusal gives the range and its source,
    /// and a value far from 1 in exponent form (`must be within [0.5, 5] m, is 1e-9
    /// (the golf car: ...)`).
    pub fn check(&self, path: &FieldPath, v: f64) -> Result<(), FieldError> {
        finite(path, v)?;
        if self.contains(v) {
            return Ok(());
        }
        let shown = if v != 0.0 && !(1e-6..1e9).contains(&v.abs()) {
            format!("{v:e}")
        } else {
            v.to_string()
        };
        Err(FieldError::new(
            path.clone(),
            format!(
                "{} ({})",
                outside(self.lo, self.hi, self.unit, &shown),
                self.source
            ),
        ))
    }

    pub fn contains(&self, v: f64) -> bool {
        (self.lo..=self.hi).contains(&v)
    }
}

/// One row of a range table: a field (keys from the table's root), how to read it from
/// a `T` (`None`: the field is not set, nothing to check), and its range.
#[derive(Debug)]
pub struct Bound<T> {
    pub field: &'static [&'static str],
    pub value: fn(&T) -> Option<f64>,
    pub range: Range,
}

/// Every row of `table` checked against `t`, in order; the first field out of its
/// range is the error.
pub fn check_bounds<T>(t: &T, table: &[Bound<T>]) -> Result<(), FieldError> {
    for row in table {
        if let Some(v) = (row.value)(t) {
            row.range.check(&FieldPath::of(row.field), v)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = "name = \"x\"\n\n[gps]\nrate_hz = 10\n\n[gps.rtk]\nhorizontal_sigma_m = -1\n\n[[obstacles]]\nkind = \"circle\"\nx = 1\n\n[[obstacles]]\nkind = \"circle\"\nradius = 0\n";

    #[test]
    fn a_file_that_cannot_be_read_is_named_with_the_reason_once() {
        let e = read_file(std::path::Path::new("/nonexistent/scenario.toml")).unwrap_err();
        let text = e.to_string();
        assert!(text.starts_with("/nonexistent/scenario.toml: "), "{text}");
        assert_eq!(text.matches("os error").count(), 1, "{text}");
        assert!(std::error::Error::source(&e).is_none(), "{text}");
    }

    #[test]
    fn paths_print_keys_and_indices() {
        let p = FieldPath::of(&["obstacles"])
            .index(1)
            .key("motion")
            .key("speed");
        assert_eq!(p.to_string(), "obstacles[1].motion.speed");
        assert_eq!(FieldPath::root().to_string(), "(the file)");
        assert_eq!(
            FieldPath::of(&["rtk", "sigma"])
                .under(&FieldPath::of(&["gps"]))
                .to_string(),
            "gps.rtk.sigma"
        );
    }

    #[test]
    fn nested_fields_and_array_elements_are_found_on_their_own_line() {
        let nested = FieldPath::of(&["gps", "rtk", "horizontal_sigma_m"]);
        assert_eq!(nested.line_in(TEXT), 7);
        let element = FieldPath::of(&["obstacles"]).index(1).key("radius");
        assert_eq!(element.line_in(TEXT), 15);
        // A field the file leaves to its default: the table that would hold it.
        let absent = FieldPath::of(&["gps", "baud"]);
        assert_eq!(absent.line_in(TEXT), 3);
        assert_eq!(FieldPath::of(&["sim", "seed"]).line_in(TEXT), 1);
        assert_eq!(nested.line_in("not [ toml"), 1);
    }

    #[test]
    fn located_errors_name_file_line_and_field() {
        let e = FieldError::new(
            FieldPath::of(&["gps", "rtk", "horizontal_sigma_m"]),
            "must be positive",
        )
        .located(TEXT, "s.toml");
        assert_eq!(
            e.to_string(),
            "s.toml:7: gps.rtk.horizontal_sigma_m: must be positive"
        );
    }

    #[test]
    fn checks_refuse_non_finite_signs_and_out_of_range_values() {
        let p = FieldPath::of(&["a"]);
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(finite(&p, v).is_err());
            assert!(positive(&p, v).is_err());
            assert!(non_negative(&p, v).is_err());
            assert!(within(&p, v, -1.0, 1.0, "").is_err());
        }
        assert!(positive(&p, 0.0).is_err());
        assert!(non_negative(&p, -1e-9).is_err());
        assert!(non_negative(&p, 0.0).is_ok());
        assert!(coordinate(&p, 1e39).is_err());
        assert!(coordinate(&p, -99_999.0).is_ok());
        let e = within(&p, 7.0, 0.0, 5.0, "m").err().map(|e| e.message);
        assert_eq!(e.as_deref(), Some("must be within [0, 5] m, is 7"));
    }

    #[test]
    fn ranges_name_their_bounds_and_source_and_tables_check_every_row() {
        struct Car {
            wheelbase: f64,
            limit: Option<f64>,
        }
        const TABLE: &[Bound<Car>] = &[
            Bound {
                field: &["vehicle", "wheelbase"],
                value: |c| Some(c.wheelbase),
                range: Range::new(0.5, 5.0, "m", "the golf car"),
            },
            Bound {
                field: &["goal", "speed_limit"],
                value: |c| c.limit,
                range: Range::new(0.1, 10.0, "m/s", "the DBC"),
            },
        ];
        let ok = Car {
            wheelbase: 1.65,
            limit: None,
        };
        assert_eq!(check_bounds(&ok, TABLE), Ok(()));
        let e = check_bounds(
            &Car {
                wheelbase: 1e-9,
                limit: None,
            },
            TABLE,
        )
        .err()
        .map(|e| e.to_string());
        assert_eq!(
            e.as_deref(),
            Some("vehicle.wheelbase: must be within [0.5, 5] m, is 1e-9 (the golf car)")
        );
        let e = check_bounds(
            &Car {
                limit: Some(f64::NAN),
                ..ok
            },
            TABLE,
        )
        .err()
        .map(|e| e.path.to_string());
        assert_eq!(e.as_deref(), Some("goal.speed_limit"));
        assert!(TABLE[0].range.contains(5.0) && !TABLE[0].range.contains(5.01));
    }
}
