//! Comparing the replayed controller's commands with the recorded ones: exactly (the
//! same frames, bytes and instants) or within a tolerance (an envelope in time, value
//! signals within some scale steps).

use std::collections::BTreeMap;

use golf_car_can::spec::NetworkSpec;
use serde::Serialize;
use ugv_controller::control::COMMAND_PERIOD;

use super::read::Command;
use crate::record::RecordMode;

/// How close a replayed command must come to the recorded ones.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Tolerance {
    /// How far apart in time a replayed and a recorded command may be, seconds: a
    /// replayed command agrees when each signal lies within the range the recorded
    /// commands of its message take over +- this (an envelope in time).
    pub window_s: f64,
    /// How far each value signal may lie outside that range, in units of its DBC
    /// scale factor (0: the bytes must be equal, counter and CRC included). States,
    /// flags and gears must lie within it.
    pub steps: f64,
    /// Signals are judged from this long after the controller's start, seconds
    /// (before, its frames are only counted: missing or extra ones still diverge).
    pub settle_s: f64,
}

impl Tolerance {
    /// SIL: the same frames, bytes and instants.
    pub const EXACT: Tolerance = Tolerance {
        window_s: 0.0,
        steps: 0.0,
        settle_s: 0.0,
    };
    /// HIL: within five command periods (50 ms: the controller process sends on its
    /// own clock, up to 25 ms late in the emulated VM, and the replay ticks on SIL's
    /// grid), value signals within 10 scale steps (0.1 degree of steering, 0.1 m/s of
    /// speed, 5 % of brake), states, flags and gears within the range, all from 1.5 s
    /// after the controller's start; counter and CRC not compared (they follow the
    /// number of frames sent, which the two runs need not share). The settling: the
    /// recorded process read fixes before its first frame and got its first plans
    /// back from its planning thread at instants the recording cannot show, and its
    /// first paths, planned from that start, differ by up to a few degrees of steering
    /// until the replannings after them agree.
    pub const HIL: Tolerance = Tolerance {
        window_s: 5.0 * COMMAND_PERIOD,
        steps: 10.0,
        settle_s: 1.5,
    };

    /// SIL's recordings and the controller's own replay exactly (the same inputs at
    /// the same ticks, the replannings taken at the recorded ticks); HIL's within
    /// [`Tolerance::HIL`].
    pub fn for_mode(mode: RecordMode) -> Tolerance {
        match mode {
            RecordMode::Sil | RecordMode::Lockstep | RecordMode::Field => Tolerance::EXACT,
            RecordMode::Hil => Tolerance::HIL,
        }
    }
}

/// Where the replay first differed from the recording.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Divergence {
    /// Simulated seconds.
    pub time_s: f64,
    pub message: String,
    /// The first signal that differs (absent when a frame is missing or extra).
    pub signal: Option<String>,
    pub recorded: Option<String>,
    pub replayed: Option<String>,
}

/// Per message: commands compared and the largest signal difference.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MessageStats {
    pub replayed: u64,
    pub recorded: u64,
    pub matched: u64,
    /// Largest |replayed - recorded| per signal, physical units.
    pub max_diff: BTreeMap<String, f64>,
}

/// Compares the replayed controller's commands with the recorded ones, as they come.
pub(super) struct Comparer<'a> {
    spec: &'a NetworkSpec,
    tol: Tolerance,
    recorded: Vec<(Command, bool)>,
    /// Recorded commands before this index are matched or out of the window.
    first_open: usize,
    pub messages: BTreeMap<String, MessageStats>,
    pub divergence: Option<Divergence>,
    epoch_ns: u64,
    /// Value signals are judged from this instant (the controller's start plus the
    /// tolerance's settling), ns on the log time.
    judged_from_ns: u64,
    /// Commands are judged before this instant only (a recording cut by a kill: see
    /// [`Comparer::new`]), ns on the log time.
    judged_until_ns: u64,
}

impl<'a> Comparer<'a> {
    /// A comparer of `recorded` (in time order) within `tol`, signals judged from
    /// `judged_from_ns`, commands before `whole_until_ns` only (`u64::MAX`: all).
    ///
    /// A recording cut by a kill holds every input and every command before
    /// `whole_until_ns` and perhaps only some of those at or after it. A replayed
    /// command at tick `t` is compared with the recorded ones within `t` +- the window:
    /// all of them are there, and so are the inputs the tick took, when `t` + window
    /// < `whole_until_ns`; a recorded command at `c` can only have been matched by
    /// ticks up to `c` + window. So commands (replayed and recorded) are judged
    /// before `whole_until_ns` - window only; a replayed command after that still
    /// covers the recorded ones it agrees with, and nothing there is counted or
    /// reported. (SIL's and the controller's own recordings: window 0, every command
    /// before the first instant that may be partly missing.)
    pub fn new(
        spec: &'a NetworkSpec,
        tol: Tolerance,
        recorded: &[Command],
        epoch_ns: u64,
        judged_from_ns: u64,
        whole_until_ns: u64,
    ) -> Comparer<'a> {
        let window = (tol.window_s * 1e9).round() as u64;
        let mut cmp = Comparer {
            spec,
            tol,
            recorded: recorded.iter().cloned().map(|c| (c, false)).collect(),
            first_open: 0,
            messages: BTreeMap::new(),
            divergence: None,
            epoch_ns,
            judged_from_ns,
            judged_until_ns: whole_until_ns.saturating_sub(window),
        };
        for c in recorded.iter().filter(|c| c.ns < cmp.judged_until_ns) {
            let name = cmp.name(c.id);
            cmp.messages.entry(name).or_default().recorded += 1;
        }
        cmp
    }

    fn window_ns(&self) -> u64 {
        (self.tol.window_s * 1e9).round() as u64
    }

    fn name(&self, id: u32) -> String {
        u16::try_from(id)
            .ok()
            .and_then(|i| self.spec.message(i))
            .map_or_else(|| format!("{id:#x}"), |m| m.name.to_string())
    }

    /// Simulated seconds of log time `ns`: negative before the simulator's clock
    /// started (a controller on its own board sends while the simulator waits for it).
    pub fn time(&self, ns: u64) -> f64 {
        (i128::from(ns) - i128::from(self.epoch_ns)) as f64 * 1e-9
    }

    fn diverge(&mut self, d: Divergence) {
        if self.divergence.is_none() {
            self.divergence = Some(d);
        }
    }

    /// Signals of a frame: name, physical value and the difference allowed (Counter
    /// and Crc left out unless exact). A state, a flag or a gear (a signal with a
    /// value table, or of one bit) must agree exactly: ten steps of a mode are
    /// another mode.
    fn signals(&self, id: u32, data: &[u8]) -> Vec<(String, f64, f64)> {
        let Some(m) = u16::try_from(id).ok().and_then(|i| self.spec.message(i)) else {
            return Vec::new();
        };
        let Ok(p) = golf_car_can::codec::payload("", data) else {
            return Vec::new();
        };
        m.signals
            .iter()
            .zip(m.decode_all(&p))
            .filter(|(_, v)| self.tol.steps == 0.0 || !matches!(v.name, "Counter" | "Crc"))
            .map(|(s, v)| {
                let allowed = if s.size == 1 || !s.values.is_empty() {
                    0.0
                } else {
                    self.tol.steps * s.factor.abs()
                };
                (v.name.to_owned(), v.value, allowed)
            })
            .collect()
    }

    /// Recorded commands that fell out of the window before `ns` without a match
    /// (those not judged, after a cut, aside).
    pub fn close_before(&mut self, ns: u64) {
        let window = self.window_ns();
        while let Some((c, matched)) = self.recorded.get(self.first_open) {
            if c.ns.saturating_add(window) >= ns {
                break;
            }
            if !matched && c.ns < self.judged_until_ns {
                let d = Divergence {
                    time_s: self.time(c.ns),
                    message: self.name(c.id),
                    signal: None,
                    recorded: Some(hex(&c.data)),
                    replayed: None,
                };
                self.diverge(d);
            }
            self.first_open += 1;
        }
    }

    /// The recorded commands of `id` within the window of `ns`.
    fn candidates(&self, ns: u64, id: u32) -> Vec<usize> {
        let window = self.window_ns();
        (self.first_open..self.recorded.len())
            .take_while(|&i| self.recorded[i].0.ns <= ns + window)
            .filter(|&i| {
                let c = &self.recorded[i].0;
                c.id == id && c.ns + window >= ns
            })
            .collect()
    }

    /// A replayed command: it agrees when some recorded command of the same message
    /// within the window agrees with it on every signal (an envelope in time: the two
    /// controllers may change a state or a value a tick or two apart), and every
    /// recorded command it agrees with is covered. It diverges when none does (the
    /// difference reported against the recorded command nearest in time), or when no
    /// recorded command of the message is within the window at all (an extra frame).
    pub fn replayed(&mut self, ns: u64, id: u32, data: &[u8]) {
        let judged = ns < self.judged_until_ns;
        let name = self.name(id);
        if judged {
            self.messages.entry(name.clone()).or_default().replayed += 1;
        }
        let candidates = self.candidates(ns, id);
        let Some(&nearest) = candidates
            .iter()
            .min_by_key(|&&i| self.recorded[i].0.ns.abs_diff(ns))
        else {
            if judged {
                let d = Divergence {
                    time_s: self.time(ns),
                    message: name,
                    signal: None,
                    recorded: None,
                    replayed: Some(hex(data)),
                };
                self.diverge(d);
            }
            return;
        };
        let (ours, least, agreed) = self.envelope(ns, id, data, &candidates);
        if agreed {
            for &i in &candidates {
                self.recorded[i].1 = true;
            }
        }
        if !judged {
            return;
        }
        let stats = self.messages.entry(name.clone()).or_default();
        for ((signal, _, allowed), diff) in ours.iter().zip(&least) {
            if allowed.is_infinite() {
                continue;
            }
            let max = stats.max_diff.entry(signal.clone()).or_insert(0.0);
            *max = max.max(*diff);
        }
        if agreed {
            stats.matched += 1;
            return;
        }
        let rec = self.recorded[nearest].0.clone();
        let theirs = self.signals(id, &rec.data);
        // The first signal outside the envelope, with the nearest recorded value.
        let (signal, recorded, replayed) = ours
            .iter()
            .zip(&theirs)
            .zip(&least)
            .find(|(((_, _, allowed), _), diff)| **diff > allowed + 1e-9)
            .map_or(
                ("(bytes)".to_owned(), 0.0, 0.0),
                |(((n, a, _), (_, b, _)), _)| (n.clone(), *b, *a),
            );
        let d = Divergence {
            time_s: self.time(ns),
            message: name,
            recorded: Some(format!("{recorded} ({})", hex(&rec.data))),
            replayed: Some(format!("{replayed} ({})", hex(data))),
            signal: Some(signal),
        };
        self.diverge(d);
    }

    /// A replayed frame's signals (name, value, difference allowed), how far each lies
    /// outside the range the `candidates` take, and whether it agrees with them.
    fn envelope(
        &self,
        ns: u64,
        id: u32,
        data: &[u8],
        candidates: &[usize],
    ) -> (Vec<(String, f64, f64)>, Vec<f64>, bool) {
        // While the controller settles, its signals are not judged (its frames are
        // counted all the same).
        let settling = ns < self.judged_from_ns;
        let ours: Vec<(String, f64, f64)> = self
            .signals(id, data)
            .into_iter()
            .map(|(n, v, allowed)| (n, v, if settling { f64::INFINITY } else { allowed }))
            .collect();
        // Per signal, the recorded values' range over the window, and how far outside
        // it the replayed value lies.
        let mut range: Vec<(f64, f64)> = vec![(f64::INFINITY, f64::NEG_INFINITY); ours.len()];
        let mut same_bytes = false;
        for &i in candidates {
            let rec = &self.recorded[i].0;
            same_bytes |= data == rec.data.as_slice();
            for (k, (_, b, _)) in self
                .signals(id, &rec.data)
                .iter()
                .enumerate()
                .take(ours.len())
            {
                range[k] = (range[k].0.min(*b), range[k].1.max(*b));
            }
        }
        let least: Vec<f64> = ours
            .iter()
            .zip(&range)
            .map(|((_, a, _), (lo, hi))| (lo - a).max(a - hi).max(0.0))
            .collect();
        let agreed = (self.tol.steps > 0.0 || same_bytes || settling)
            && ours
                .iter()
                .zip(&least)
                .all(|((_, _, allowed), diff)| *diff <= allowed + 1e-9);
        (ours, least, agreed)
    }
}

/// Bytes as upper-case hex.
pub(super) fn hex(data: &[u8]) -> String {
    data.iter().map(|b| format!("{b:02X}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hil_tolerance_allows_steps_on_values_but_not_on_states() {
        let spec = NetworkSpec::from_dbc(golf_car_can::GOLF_CAR_DBC).unwrap();
        let steering = spec
            .messages
            .iter()
            .find(|m| m.name == "STEERING_CMD")
            .unwrap();
        let cmp = Comparer::new(&spec, Tolerance::HIL, &[], 0, 0, u64::MAX);
        let frame = [1u8, 0, 0, 0, 0, 0, 0, 0];
        let allowed: BTreeMap<String, f64> = cmp
            .signals(u32::from(steering.id), &frame)
            .into_iter()
            .map(|(name, _, allowed)| (name, allowed))
            .collect();
        assert_eq!(allowed["Enable"], 0.0, "{allowed:?}");
        let angle = steering
            .signals
            .iter()
            .find(|s| s.name == "TargetAngle")
            .unwrap();
        assert!((allowed["TargetAngle"] - 10.0 * angle.factor.abs()).abs() < 1e-12);
        assert!(!allowed.contains_key("Counter") && !allowed.contains_key("Crc"));
    }

    /// A recording cut at 100 ms: the recorded commands there and after may be lost
    /// (here: the one at 100 ms is), and the replayed ones there are not judged; HIL's
    /// window takes 50 ms more off the end.
    #[test]
    fn commands_at_and_after_the_cut_are_not_judged() {
        let spec = NetworkSpec::from_dbc(golf_car_can::GOLF_CAR_DBC).unwrap();
        let ms = 1_000_000;
        let beat = |ns: u64| Command {
            ns,
            id: 0x80,
            data: vec![0; 8],
        };
        let recorded = [beat(80 * ms), beat(90 * ms)];
        let mut cmp = Comparer::new(&spec, Tolerance::EXACT, &recorded, 0, 0, 100 * ms);
        for at in [80, 90, 100, 110] {
            cmp.close_before(at * ms);
            cmp.replayed(at * ms, 0x80, &[0; 8]);
        }
        cmp.close_before(u64::MAX);
        assert_eq!(cmp.divergence, None);
        let stats = &cmp.messages["CONTROLLER_HEARTBEAT"];
        assert_eq!((stats.recorded, stats.replayed, stats.matched), (2, 2, 2));
        // Without the cut, the frames at 100 and 110 ms are extra.
        let mut whole = Comparer::new(&spec, Tolerance::EXACT, &recorded, 0, 0, u64::MAX);
        for at in [80, 90, 100] {
            whole.replayed(at * ms, 0x80, &[0; 8]);
        }
        assert_eq!(whole.divergence.map(|d| d.time_s), Some(0.1));
        // HIL: judged before 100 - 50 ms: a recorded command at 75 ms that nothing
        // matched is not judged (a replayed one at up to 125 ms could have).
        let recorded = [beat(20 * ms), beat(75 * ms)];
        let mut hil = Comparer::new(&spec, Tolerance::HIL, &recorded, 0, 0, 100 * ms);
        hil.replayed(20 * ms, 0x80, &[0; 8]);
        hil.close_before(u64::MAX);
        assert_eq!(hil.divergence, None);
        assert_eq!(hil.messages["CONTROLLER_HEARTBEAT"].recorded, 1);
        let mut whole = Comparer::new(&spec, Tolerance::HIL, &recorded, 0, 0, u64::MAX);
        whole.replayed(20 * ms, 0x80, &[0; 8]);
        whole.close_before(u64::MAX);
        let at = whole.divergence.map(|d| d.time_s).unwrap();
        assert!((at - 0.075).abs() < 1e-9, "{at}");
    }
}
