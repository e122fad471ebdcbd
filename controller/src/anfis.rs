//! ANFIS: adaptive-network-based fuzzy inference system (Jang 1993, IEEE SMC 23(3)),
//! the learner behind the seed paper's ANFIS path follower.
//!
//! # The network (first-order Sugeno, N inputs, R rules)
//!
//! Every input x_i is first mapped to u_i in [-1, 1] over its normalisation range
//! [lo_i, hi_i] (stored in the model; the training data's range unless configured):
//!
//! ```text
//! u_i = 2 (x_i - lo_i) / (hi_i - lo_i) - 1
//! ```
//!
//! Inputs outside the range are extrapolated, not clamped. All premise and consequent
//! parameters live in these normalised units.
//!
//! 1. Layer 1, membership grades: the generalised bell ([`BellMf`])
//!    `mu_ij(u_i) = 1 / (1 + |(u_i - c_ij) / a_ij|^(2 b_ij))`, a > 0, b > 0.
//! 2. Layer 2, firing strengths: rule r takes one MF per input (its antecedent m_r)
//!    and `w_r = prod_i mu_{i, m_r(i)}(u_i)`. Training builds the full grid: with
//!    `[3, 3]` MFs there are 9 rules, the last input's MF index varying fastest.
//! 3. Layer 3, normalisation: `wbar_r = w_r / sum_k w_k`.
//! 4. Layer 4, consequents: `f_r = p_r . u + r_r`.
//! 5. Layer 5, output: `o = sum_r wbar_r f_r`.
//!
//! Layers 2-3 are evaluated in the log domain (`ln w_r = sum_i ln mu`, then a
//! max-shifted softmax), which is the same function but stays finite where every w_r
//! underflows to zero in f64 (an input far from every MF): there the output is the
//! limit of the formula instead of 0/0.
//!
//! # Hybrid learning ([`train`])
//!
//! Each epoch, with E = sum_p (t_p - o_p)^2 over the training data:
//!
//! * forward pass, premises fixed: o is linear in the consequents,
//!   `o_p = sum_r [wbar_r u_p, wbar_r] . [p_r, r_r]`, so they are the least-squares
//!   solution of A theta = t (A is P x R (N + 1)). It is solved by a singular value
//!   decomposition (nalgebra), treating singular values below
//!   `sigma_max * max(P, R (N + 1)) * f64::EPSILON` as zero, which gives the
//!   minimum-norm solution when A is rank deficient (few data, rules that never fire).
//!   This is the batch equivalent of Jang's sequential LSE, without its
//!   initial-covariance approximation. The epoch's error is recorded here.
//! * backward pass, consequents fixed: gradient descent on (a, b, c). With
//!   `l_ij = ln mu_ij` the analytic derivatives are
//!   `do/dl_ij = sum_{r: m_r(i) = j} wbar_r (f_r - o)` and, with z = (u - c) / a,
//!   `dl/da = 2 b (1 - mu) / a`, `dl/dc = 2 b (1 - mu) / (z a)` (0 at z = 0),
//!   `dl/db = -2 (1 - mu) ln|z|` (0 at z = 0); `dE/do_p = -2 (t_p - o_p)`.
//!   Jang's step: `delta = -k g / |g|` (a step of length k in parameter space), then
//!   a is clamped to `a >= min_width` and b to `b >= min_shape`.
//! * Jang's step-size rules: k grows by 10% after four consecutive decreases of the
//!   error and shrinks by 10% after two consecutive increase/decrease alternations
//!   (four changes alternating in sign); each rule then waits four epochs before it
//!   may fire again (as MATLAB's `anfis` does).
//!
//! Initialisation (Jang): per input, m MFs with centres evenly spaced over [-1, 1]
//! (the normalisation range), `a` half the spacing and `b = 2`, so neighbouring MFs
//! cross at grade 0.5; a single MF sits at 0 with `a = 1`.
//!
//! The returned model is the epoch with the lowest training error (or checking error,
//! [`ModelSelection`]); its consequents are the least-squares ones for its premises.

mod bell;
mod command;
mod data;
mod model;
mod train;

use std::path::PathBuf;

pub use bell::{BellGradient, BellMf};
pub use command::{TrainArgs, train_command};
pub use data::{DataFormat, Dataset};
pub use model::{AnfisModel, InputSpec, MODEL_FORMAT, MODEL_VERSION, ModelSpec, RuleSpec};
pub use train::{
    MAX_DESIGN_CELLS, MAX_EPOCHS, MAX_INITIAL_STEP, MAX_MFS_PER_INPUT, MAX_RULES, ModelSelection,
    TrainConfig, TrainReport, train, train_with_checking,
};

/// Everything that can go wrong in the ANFIS module.
#[derive(Debug, thiserror::Error)]
pub enum AnfisError {
    /// A model (JSON or built by hand) breaks an invariant; `field` is its path in the
    /// JSON document, e.g. `inputs[1].mfs[0].a`.
    #[error("invalid ANFIS model: {field}: {reason}")]
    InvalidModel { field: String, reason: String },
    /// A training configuration value is out of range.
    #[error("invalid ANFIS training configuration: {field}: {reason}")]
    InvalidConfig { field: String, reason: String },
    /// `predict` got the wrong number of inputs.
    #[error("expected {expected} inputs, got {found}")]
    InputLength { expected: usize, found: usize },
    /// `predict` got NaN or an infinity.
    #[error("input {index} ({name}) is not a finite number ({value})")]
    NonFiniteInput {
        index: usize,
        name: String,
        value: f64,
    },
    /// The network produced NaN or an infinity (inputs or parameters so extreme that
    /// f64 overflows).
    #[error("numerical failure: {reason}")]
    Numerical { reason: String },
    /// A training or checking data set is malformed.
    #[error("invalid data: {reason}")]
    InvalidData { reason: String },
    /// A data column requested by name does not exist.
    #[error("no column named '{name}' (available: {available})")]
    MissingColumn { name: String, available: String },
    /// A CSV cell or line is malformed; `line` is 1-based.
    #[error("CSV line {line}, column '{column}': {reason}")]
    Csv {
        line: usize,
        column: String,
        reason: String,
    },
    /// A JSON data value is malformed; `location` names the element and field.
    #[error("JSON data {location}: {reason}")]
    JsonData { location: String, reason: String },
    /// JSON that does not parse or does not fit the expected schema.
    #[error("{what}: {source}")]
    Json {
        what: String,
        source: serde_json::Error,
    },
    /// An input's range is empty (every training value equal), so it cannot be
    /// normalised.
    #[error("input '{name}' has an empty range [{lo}, {hi}]: it cannot be normalised")]
    DegenerateRange { name: String, lo: f64, hi: f64 },
    /// The data format cannot be told from the file name.
    #[error(
        "{path}: cannot tell the data format from the extension (use .csv or .json, or name the format)"
    )]
    UnknownFormat { path: PathBuf },
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// An error inside a named file.
    #[error("{path}: {error}")]
    InFile {
        path: PathBuf,
        error: Box<AnfisError>,
    },
}

impl AnfisError {
    fn in_file(path: &std::path::Path, error: AnfisError) -> Self {
        AnfisError::InFile {
            path: path.to_path_buf(),
            error: Box::new(error),
        }
    }

    /// The innermost error (through [`AnfisError::InFile`]).
    pub fn innermost(&self) -> &AnfisError {
        match self {
            AnfisError::InFile { error, .. } => error.innermost(),
            other => other,
        }
    }
}
