//! Which loop runs a scenario.

use std::fmt;

use serde::{Deserialize, Serialize};

/// HIL (the controller binary in its own process on the real wires, wall-clock time) or
/// SIL (the controller library in lockstep with the simulator); written `"hil"` and
/// `"sil"` in verdicts, suite summaries and recordings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    Sil,
    Hil,
}

impl Mode {
    /// `"sil"` or `"hil"`, as serialised.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Sil => "sil",
            Mode::Hil => "hil",
        }
    }
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modes_serialise_as_their_lower_case_names() {
        for (mode, text) in [(Mode::Sil, "sil"), (Mode::Hil, "hil")] {
            assert_eq!(serde_json::to_string(&mode).unwrap(), format!("\"{text}\""));
            assert_eq!(mode.as_str(), text);
            assert_eq!(mode.to_string(), text);
            let back: Mode = serde_json::from_str(&format!("\"{text}\"")).unwrap();
            assert_eq!(back, mode);
        }
        assert!(serde_json::from_str::<Mode>("\"SIL\"").is_err());
    }
}
