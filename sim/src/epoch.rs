//! The scenario's epoch: UTC at simulated time zero, parsed once at load.

use chrono::{DateTime, SecondsFormat, Utc};

/// The earliest epoch a run may have: the start of GPS time (1980-01-06T00:00:00Z).
const EARLIEST_S: i64 = 315_964_800;
/// The latest: 2200-01-01T00:00:00Z (nanoseconds since 1970 still fit a u64).
const LATEST_S: i64 = 7_258_118_400;

/// UTC at simulated time zero (`sim.epoch`, RFC 3339 in the file).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Epoch(DateTime<Utc>);

impl Epoch {
    /// An RFC 3339 time (`2026-05-04T14:00:00Z`, `2026-05-04T14:00:00.25Z`, or with a
    /// `+hh:mm` offset) between 1980-01-06 and 2200-01-01.
    pub fn parse(text: &str) -> Result<Epoch, String> {
        let shown: String = text.chars().take(64).collect();
        let t = DateTime::parse_from_rfc3339(text)
            .map_err(|e| {
                format!("{shown:?} is not an RFC 3339 time ({e}); e.g. 2026-05-04T14:00:00Z")
            })?
            .with_timezone(&Utc);
        if !(EARLIEST_S..LATEST_S).contains(&t.timestamp()) {
            return Err(format!(
                "{shown:?} is outside 1980-01-06 (GPS time zero) .. 2200-01-01"
            ));
        }
        Ok(Epoch(t))
    }

    pub fn utc(&self) -> DateTime<Utc> {
        self.0
    }

    /// Seconds since 1970-01-01T00:00:00Z.
    pub fn unix_s(&self) -> f64 {
        self.0.timestamp() as f64 + f64::from(self.0.timestamp_subsec_nanos()) * 1e-9
    }

    /// Nanoseconds since 1970-01-01T00:00:00Z.
    pub fn unix_ns(&self) -> u64 {
        // Within [EARLIEST_S, LATEST_S) by construction.
        u64::try_from(self.0.timestamp()).unwrap_or(0) * 1_000_000_000
            + u64::from(self.0.timestamp_subsec_nanos())
    }
}

impl Default for Epoch {
    fn default() -> Self {
        // 2026-05-04T14:00:00Z.
        Epoch(DateTime::from_timestamp(1_777_903_200, 0).unwrap_or_default())
    }
}

impl std::fmt::Display for Epoch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0.to_rfc3339_opts(SecondsFormat::AutoSi, true))
    }
}

impl serde::Serialize for Epoch {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> serde::Deserialize<'de> for Epoch {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        Epoch::parse(&text).map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rfc3339_against_known_epochs() {
        let s = |t: &str| Epoch::parse(t).map(|e| e.unix_s());
        // 2000-03-01 is day 11017 since 1970 (30 years, 7 of them leap, + Jan + Feb 29).
        let days = 30 * 365 + 7 + 31 + 29;
        assert_eq!(s("2000-03-01T00:00:00Z"), Ok((days * 86_400) as f64));
        assert_eq!(s("2000-03-01T01:30:00+01:30"), s("2000-03-01T00:00:00Z"));
        assert_eq!(s("2026-05-04T14:00:00.25Z").map(|t| t.fract()), Ok(0.25));
        assert_eq!(Epoch::default().to_string(), "2026-05-04T14:00:00Z");
        assert_eq!(Epoch::parse("2026-05-04T14:00:00Z"), Ok(Epoch::default()));
        assert_eq!(
            Epoch::parse("2026-05-04T14:00:00Z").map(|e| e.unix_ns()),
            Ok(1_777_903_200_000_000_000)
        );
        for bad in [
            "2026-02-30T00:00:00Z",
            "2026-05-04 14:00",
            "yesterday",
            "2026-05-04T25:00:00Z",
        ] {
            assert!(Epoch::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn huge_years_and_offsets_are_refused_not_overflowed() {
        for bad in [
            "99999999999-01-01T00:00:00Z",
            "9999-12-31T23:59:59Z",
            "1969-12-31T23:59:59Z",
            "2026-05-04T14:00:00+99999999999:00",
            "2026-05-04T14:00:00+24:00",
            "2026-05-04T14:00:99999999999999999999Z",
        ] {
            let e = Epoch::parse(bad);
            assert!(e.is_err(), "{bad}: {e:?}");
        }
        // A 20 MiB value is named in 64 characters, not echoed whole.
        let long = "9".repeat(20 << 20);
        let message = Epoch::parse(&long).err().unwrap_or_default();
        assert!(message.len() < 300, "{}", message.len());
    }
}
