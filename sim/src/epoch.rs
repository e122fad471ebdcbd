//! The scenario's epoch: UTC at simulated time zero.

/// Seconds since 1970-01-01T00:00:00Z of an RFC 3339 UTC time
/// (`2026-05-04T14:00:00Z`, `2026-05-04T14:00:00.25Z`, or with a `+hh:mm` offset).
pub fn parse_rfc3339(text: &str) -> Result<f64, String> {
    let err = |what: &str| {
        format!("{text:?} is not an RFC 3339 time ({what}); e.g. 2026-05-04T14:00:00Z")
    };
    let (date, time) = text
        .split_once(['T', 't', ' '])
        .ok_or_else(|| err("no 'T' between date and time"))?;
    let num = |s: &str, what: &str| s.parse::<i64>().map_err(|_| err(what));
    let d: Vec<&str> = date.split('-').collect();
    let [y, mo, da] = d.as_slice() else {
        return Err(err("date must be YYYY-MM-DD"));
    };
    let (y, mo, da) = (num(y, "year")?, num(mo, "month")?, num(da, "day")?);
    let (clock, offset) = if let Some(c) = time.strip_suffix(['Z', 'z']) {
        (c, 0)
    } else if let Some(i) = time.rfind(['+', '-']) {
        let (c, off) = time.split_at(i);
        let sign = if off.starts_with('-') { -1 } else { 1 };
        let (oh, om) = off[1..]
            .split_once(':')
            .ok_or_else(|| err("offset must be +hh:mm"))?;
        (
            c,
            sign * (num(oh, "offset hours")? * 3600 + num(om, "offset minutes")? * 60),
        )
    } else {
        return Err(err("no time zone: end with Z or +hh:mm"));
    };
    let t: Vec<&str> = clock.split(':').collect();
    let [h, mi, s] = t.as_slice() else {
        return Err(err("time must be hh:mm:ss"));
    };
    let (h, mi) = (num(h, "hour")?, num(mi, "minute")?);
    let s: f64 = s.parse().map_err(|_| err("seconds"))?;
    let days_in_month = [
        31,
        if y % 4 == 0 && (y % 100 != 0 || y % 400 == 0) {
            29
        } else {
            28
        },
        31,
        30,
        31,
        30,
        31,
        31,
        30,
        31,
        30,
        31,
    ];
    if !(1..=12).contains(&mo) || da < 1 || da > days_in_month[(mo - 1) as usize] {
        return Err(err("no such date"));
    }
    if !(0..24).contains(&h) || !(0..60).contains(&mi) || !(0.0..61.0).contains(&s) {
        return Err(err("time out of range"));
    }
    // Days from the civil date (Howard Hinnant's algorithm).
    let yy = if mo <= 2 { y - 1 } else { y };
    let era = yy.div_euclid(400);
    let yoe = yy - era * 400;
    let mp = (mo + 9) % 12;
    let doy = (153 * mp + 2) / 5 + da - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    let days = era * 146_097 + doe - 719_468;
    Ok((days * 86_400 + h * 3600 + mi * 60 - offset) as f64 + s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rfc3339_against_known_epochs() {
        assert_eq!(parse_rfc3339("1970-01-01T00:00:00Z"), Ok(0.0));
        // 2000-03-01 is day 11017 since the epoch (30 years, 7 of them leap, + Jan + Feb 29).
        let days = 30 * 365 + 7 + 31 + 29;
        assert_eq!(
            parse_rfc3339("2000-03-01T00:00:00Z"),
            Ok((days * 86_400) as f64)
        );
        assert_eq!(
            parse_rfc3339("2000-03-01T01:30:00+01:30"),
            parse_rfc3339("2000-03-01T00:00:00Z")
        );
        assert_eq!(
            parse_rfc3339("2026-05-04T14:00:00.25Z").map(|t| t.fract()),
            Ok(0.25)
        );
        for bad in [
            "2026-02-30T00:00:00Z",
            "2026-05-04 14:00",
            "yesterday",
            "2026-05-04T25:00:00Z",
        ] {
            assert!(parse_rfc3339(bad).is_err(), "{bad}");
        }
    }
}
