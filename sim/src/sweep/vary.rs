//! `--vary KEY=SPEC`: a scenario field swept over a list of values (`a,b,c`) or a range
//! with a step (`lo:hi:step`), set in the parsed TOML document before the scenario is
//! deserialized and validated, so an override is checked exactly like a field of the
//! file.

use std::fmt;
use std::str::FromStr;

use serde::Deserialize;
use ugv_fields::{FieldPath, Segment};

use crate::scenario::{Scenario, ScenarioError};

/// Most values one `--vary` may give.
pub const MAX_VALUES: usize = 10_000;

/// One field set to one value.
#[derive(Clone, Debug, PartialEq)]
pub struct Setting {
    pub key: FieldPath,
    pub value: toml::Value,
}

impl fmt::Display for Setting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}", self.key, self.value)
    }
}

/// A field and the values it is swept over.
#[derive(Clone, Debug, PartialEq)]
pub struct Vary {
    /// The argument as given (`steering.dead_time_s=0:0.3:0.05`).
    pub spec: String,
    pub key: FieldPath,
    pub values: Vec<toml::Value>,
}

impl FromStr for Vary {
    type Err = String;

    fn from_str(arg: &str) -> Result<Vary, String> {
        let (key, spec) = arg.split_once('=').ok_or_else(|| {
            format!("{arg:?} is not KEY=SPEC (a list a,b,c or a range lo:hi:step)")
        })?;
        let key = parse_key(key.trim())?;
        let values = match range(spec)? {
            Some(values) => values,
            None => spec
                .split(',')
                .map(|v| value(v.trim()))
                .collect::<Result<Vec<_>, _>>()?,
        };
        if values.len() > MAX_VALUES {
            return Err(format!(
                "{key}: {} values, at most {MAX_VALUES} are allowed",
                values.len()
            ));
        }
        // The same value twice would plan the same deterministic runs twice and count
        // them twice in every statistic.
        for (i, v) in values.iter().enumerate() {
            if let Some(earlier) = values[..i].iter().find(|w| same_value(w, v)) {
                return Err(format!(
                    "{key}: the value {v} is given twice (as {earlier} and {v}): each value is one grid point"
                ));
            }
        }
        Ok(Vary {
            spec: arg.to_owned(),
            key,
            values,
        })
    }
}

/// `gps.rtk.horizontal_sigma_m`, `obstacles[0].radius`: keys and array indices.
fn parse_key(text: &str) -> Result<FieldPath, String> {
    let bad = |why: &str| format!("key {text:?}: {why}");
    let mut path = FieldPath::root();
    if text.is_empty() {
        return Err(bad("empty"));
    }
    for part in text.split('.') {
        let (name, mut rest) = part.split_at(part.find('[').unwrap_or(part.len()));
        if name.is_empty()
            || !name
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
        {
            return Err(bad(&format!(
                "{part:?} is not a field name (letters, digits, _ and -, then any [index])"
            )));
        }
        path = path.key(name.to_owned());
        while !rest.is_empty() {
            let close = rest
                .find(']')
                .filter(|_| rest.starts_with('['))
                .ok_or_else(|| bad(&format!("{part:?}: an index is written [N]")))?;
            let index: usize = rest[1..close]
                .parse()
                .map_err(|_| bad(&format!("{:?} is not an index", &rest[1..close])))?;
            path = path.index(index);
            rest = &rest[close + 1..];
        }
    }
    Ok(path)
}

/// A TOML value (`0.05`, `3`, `true`, `"text"`); a bare word (`vcan1`) is a string.
fn value(text: &str) -> Result<toml::Value, String> {
    toml::Value::from_str(text).or_else(|e| {
        let word = text.starts_with(|c: char| c.is_ascii_alphabetic())
            && text
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || "_-.".contains(c));
        if word {
            Ok(toml::Value::String(text.to_owned()))
        } else {
            Err(format!("{text:?} is not a value: {}", e.message()))
        }
    })
}

/// Whether two values set a field alike: equal, numbers by value (`1` and `1.0`, which
/// a float field reads alike).
fn same_value(a: &toml::Value, b: &toml::Value) -> bool {
    let number = |v: &toml::Value| match v {
        toml::Value::Integer(i) => Some(*i as f64),
        toml::Value::Float(f) => Some(*f),
        _ => None,
    };
    match (number(a), number(b)) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}

/// Decimal places written in a number (`0.05` has 2), when it is written without an
/// exponent.
fn decimals(text: &str) -> Option<i32> {
    if text.contains(['e', 'E']) {
        return None;
    }
    Some(text.split_once('.').map_or(0, |(_, f)| f.len() as i32))
}

/// `lo:hi:step` as its values, from lo up to hi (included when a step lands on it);
/// integers when all three are, floats rounded to the places written. `None` when the
/// spec is not three numbers separated by colons (a list).
fn range(spec: &str) -> Result<Option<Vec<toml::Value>>, String> {
    let parts: Vec<&str> = spec.split(':').map(str::trim).collect();
    let [lo, hi, step] = parts[..] else {
        return Ok(None);
    };
    let (Ok(l), Ok(h), Ok(s)) = (lo.parse::<f64>(), hi.parse::<f64>(), step.parse::<f64>()) else {
        return Ok(None);
    };
    if !(l.is_finite() && h.is_finite() && s.is_finite() && s > 0.0) {
        return Err(format!(
            "range {spec:?}: lo, hi and step must be finite numbers and the step positive"
        ));
    }
    if h < l {
        return Err(format!("range {spec:?}: hi is below lo"));
    }
    let steps = ((h - l) / s * (1.0 + 1e-12) + 1e-9).floor();
    if steps >= MAX_VALUES as f64 {
        return Err(format!(
            "range {spec:?}: {steps} steps, at most {MAX_VALUES} values are allowed"
        ));
    }
    let count = steps as usize + 1;
    let ints = (lo.parse::<i64>(), step.parse::<i64>(), hi.parse::<i64>());
    if let (Ok(lo), Ok(step), Ok(_)) = ints {
        return Ok(Some(
            (0..count as i64)
                .map(|i| toml::Value::Integer(lo + i * step))
                .collect(),
        ));
    }
    let places = [lo, hi, step]
        .iter()
        .map(|t| decimals(t))
        .collect::<Option<Vec<_>>>();
    let round = |v: f64| match &places {
        Some(p) => {
            let scale = 10f64.powi(p.iter().copied().max().unwrap_or(0).min(15));
            (v * scale).round() / scale
        }
        None => v,
    };
    Ok(Some(
        (0..count)
            .map(|i| toml::Value::Float(round(l + i as f64 * s)))
            .collect(),
    ))
}

/// `value` at `path` below `node`, creating the tables on the way that the file leaves
/// out (`[gps.rtk]`); arrays must already hold the element.
fn set(
    node: &mut toml::Value,
    path: &[Segment],
    at: &FieldPath,
    value: toml::Value,
) -> Result<(), String> {
    let Some((first, rest)) = path.split_first() else {
        *node = value;
        return Ok(());
    };
    match (first, node) {
        (Segment::Key(k), toml::Value::Table(t)) => {
            let here = at.key(k.clone());
            if !t.contains_key(k.as_ref()) && matches!(rest.first(), Some(Segment::Index(_))) {
                return Err(format!(
                    "{here} is not in the file: only elements of an array the file writes can be set"
                ));
            }
            let child = t
                .entry(k.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            set(child, rest, &here, value)
        }
        (Segment::Index(i), toml::Value::Array(items)) => {
            let len = items.len();
            match items.get_mut(*i) {
                Some(child) => set(child, rest, &at.index(*i), value),
                None => Err(format!("{at} has {len} elements, [{i}] is not one of them")),
            }
        }
        (Segment::Key(k), _) => Err(format!("{at} is not a table, so it has no field {k}")),
        (Segment::Index(i), _) => Err(format!("{at} is not an array, so it has no [{i}]")),
    }
}

/// The scenario of TOML `text` (the file `file`) with `settings` applied to its
/// document, deserialized and validated like the file itself; errors name the file
/// with the settings, and the field and its line in the file where it has one.
pub fn scenario_with(
    text: &str,
    file: &str,
    settings: &[Setting],
) -> Result<Scenario, ScenarioError> {
    let parse = |file: &str, message: String| ScenarioError::Parse {
        file: file.to_owned(),
        message: message.trim_end().to_owned(),
    };
    let mut doc = toml::Value::Table(
        toml::from_str::<toml::Table>(text).map_err(|e| parse(file, e.to_string()))?,
    );
    let label = format!(
        "{file} with {}",
        settings
            .iter()
            .map(Setting::to_string)
            .collect::<Vec<_>>()
            .join(", ")
    );
    for s in settings {
        set(
            &mut doc,
            s.key.segments(),
            &FieldPath::root(),
            s.value.clone(),
        )
        .map_err(|m| parse(&label, format!("{}: {m}", s.key)))?;
    }
    // toml puts "in `section`" on a line of its own.
    let scenario = Scenario::deserialize(doc)
        .map_err(|e| parse(&label, e.to_string().trim_end().replace('\n', " ")))?;
    scenario.validate().map_err(|e| e.located(text, &label))?;
    Ok(scenario)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn floats(v: &Vary) -> Vec<f64> {
        v.values.iter().filter_map(toml::Value::as_float).collect()
    }

    #[test]
    fn a_range_steps_from_lo_to_hi_rounded_to_the_places_written() {
        let v: Vary = "steering.dead_time_s=0:0.3:0.05".parse().unwrap();
        assert_eq!(v.key.to_string(), "steering.dead_time_s");
        assert_eq!(floats(&v), [0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3]);
        let v: Vary = "can.fault_clear_ms=100:300:100".parse().unwrap();
        assert_eq!(
            v.values,
            [100, 200, 300].map(toml::Value::Integer).to_vec(),
            "integers stay integers"
        );
        let v: Vary = "x=0:1:0.3".parse().unwrap();
        assert_eq!(
            floats(&v),
            [0.0, 0.3, 0.6, 0.9],
            "hi is not a step: left out"
        );
    }

    #[test]
    fn a_list_holds_toml_values_and_bare_words() {
        let v: Vary = "gps.rtk.horizontal_sigma_m=0.01, 0.05,0.1".parse().unwrap();
        assert_eq!(floats(&v), [0.01, 0.05, 0.1]);
        let v: Vary = "can.interface=vcan1,\"vcan2\"".parse().unwrap();
        assert_eq!(
            v.values,
            ["vcan1", "vcan2"]
                .map(|s| toml::Value::String(s.into()))
                .to_vec()
        );
        let v: Vary = "obstacles[1].motion.speed=2".parse().unwrap();
        assert_eq!(v.key.to_string(), "obstacles[1].motion.speed");
    }

    #[test]
    fn malformed_specs_are_refused_with_what_is_wrong() {
        for (arg, says) in [
            ("steering.dead_time_s", "is not KEY=SPEC"),
            ("=1", "empty"),
            ("steering..x=1", "is not a field name"),
            ("obstacles[a].x=1", "is not an index"),
            ("obstacles[0.x=1", "an index is written [N]"),
            ("x=1:0:0.1", "hi is below lo"),
            ("x=0:1:0", "the step positive"),
            ("x=0:1000000:1", "at most 10000"),
            ("x=1e400", "is not a value"),
            ("x=1,,2", "is not a value"),
            ("x=0.1,0.1", "x: the value 0.1 is given twice"),
            ("x=0.1,0.2,0.10", "x: the value 0.1 is given twice"),
            ("x=1,1.0", "x: the value 1.0 is given twice (as 1 and 1.0)"),
            ("x=a,b,a", "x: the value \"a\" is given twice"),
        ] {
            let e = arg.parse::<Vary>().unwrap_err();
            assert!(e.contains(says), "{arg}: {e}");
        }
    }

    const FILE: &str = "name = \"t\"\n\n[steering]\ndead_time_s = 0.02\n";

    fn setting(arg: &str) -> Vec<Setting> {
        let v: Vary = arg.parse().unwrap();
        vec![Setting {
            key: v.key,
            value: v.values[0].clone(),
        }]
    }

    #[test]
    fn a_setting_changes_the_field_and_adds_missing_tables() {
        let sc = scenario_with(FILE, "t.toml", &setting("steering.dead_time_s=0.2")).unwrap();
        assert_eq!(sc.steering.dead_time_s, 0.2);
        let sc =
            scenario_with(FILE, "t.toml", &setting("gps.rtk.horizontal_sigma_m=0.05")).unwrap();
        assert_eq!(sc.gps.rtk.horizontal_sigma_m, 0.05);
        let with_post =
            format!("{FILE}\n[[obstacles]]\nkind = \"circle\"\nx = 19.0\ny = 8.0\nradius = 3.0\n");
        let sc = scenario_with(&with_post, "t.toml", &setting("obstacles[0].radius=1.5")).unwrap();
        assert!(
            matches!(sc.obstacles[..], [crate::scenario::Obstacle::Circle { radius, .. }] if radius == 1.5),
            "{:?}",
            sc.obstacles
        );
    }

    #[test]
    fn a_bad_setting_is_refused_naming_the_field_like_a_file_field() {
        for (arg, says) in [
            (
                "steering.dead_time_s=9",
                "t.toml with steering.dead_time_s=9:4: steering.dead_time_s:",
            ),
            ("steering.dead_tim_s=0.1", "unknown field `dead_tim_s`"),
            ("steering.dead_time_s=abc", "invalid type: string \"abc\""),
            ("name.x=1", "name is not a table"),
            ("obstacles[3].radius=1", "obstacles is not in the file"),
            ("steering[0]=1", "steering is not an array"),
        ] {
            let e = scenario_with(FILE, "t.toml", &setting(arg)).unwrap_err();
            assert!(e.to_string().contains(says), "{arg}: {e}");
        }
    }
}
