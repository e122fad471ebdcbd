//! The `anfis train` subcommand, as a library function under a thin CLI.

use std::path::PathBuf;

use super::AnfisError;
use super::data::{DataFormat, Dataset};
use super::train::{
    ModelSelection, TrainConfig, TrainReport, check_epochs, check_grid, check_step, train,
    train_with_checking,
};

/// Arguments of `anfis train`.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainArgs {
    /// Training data file (CSV with a header row, or JSON).
    pub data: PathBuf,
    /// Format of the data files ([`DataFormat::Auto`]: from the extension).
    pub format: DataFormat,
    /// Input column names, in model input order (CSV: empty means every column but the
    /// target).
    pub inputs: Vec<String>,
    /// Target column name.
    pub target: String,
    /// MFs per input (one value applies to every input), each 1 to
    /// [`MAX_MFS_PER_INPUT`](super::MAX_MFS_PER_INPUT), at most
    /// [`MAX_RULES`](super::MAX_RULES) rules in all (their product over the inputs).
    pub mfs: Vec<usize>,
    /// Epochs, 1 to [`MAX_EPOCHS`](super::MAX_EPOCHS).
    pub epochs: usize,
    /// Jang's initial step size k (normalised units), 0 < k <=
    /// [`MAX_INITIAL_STEP`](super::MAX_INITIAL_STEP).
    pub step_size: f64,
    /// Where the model JSON is written.
    pub output: PathBuf,
    /// Optional checking data (same format and columns); when given, the epoch with
    /// the lowest checking RMSE is saved.
    pub checking: Option<PathBuf>,
}

impl TrainArgs {
    /// Arguments with the [`TrainConfig`] defaults for MFs, epochs and step size, and
    /// no checking data.
    pub fn new(data: PathBuf, inputs: Vec<String>, target: String, output: PathBuf) -> Self {
        let defaults = TrainConfig::default();
        TrainArgs {
            data,
            format: DataFormat::Auto,
            inputs,
            target,
            mfs: defaults.mfs_per_input,
            epochs: defaults.epochs,
            step_size: defaults.initial_step,
            output,
            checking: None,
        }
    }

    /// Checks the numbers before anything is read or allocated: every MF count, the
    /// rule grid they make over the inputs named (one count applies to each), the
    /// epochs and the step size. Errors are [`AnfisError::InvalidConfig`] naming the
    /// field (`mfs`, `epochs`, `step_size`) and the allowed range. With no inputs named
    /// (every CSV column but the target) the grid is checked once the data is read.
    pub fn validate(&self) -> Result<(), AnfisError> {
        let grid = match (self.mfs.as_slice(), self.inputs.len()) {
            ([m], n) if n > 0 => vec![*m; n],
            (list, _) => list.to_vec(),
        };
        check_grid("mfs", &grid)?;
        check_epochs("epochs", self.epochs)?;
        check_step("step_size", self.step_size)
    }
}

/// Loads the data, trains, writes the model to `args.output` and returns the report.
/// Nothing is written when anything fails.
pub fn train_command(args: &TrainArgs) -> Result<TrainReport, AnfisError> {
    args.validate()?;
    let data = Dataset::load(&args.data, args.format, &args.inputs, &args.target)?;
    let checking = match &args.checking {
        Some(path) => Some(Dataset::load(
            path,
            args.format,
            data.input_names(),
            &args.target,
        )?),
        None => None,
    };
    let config = TrainConfig {
        mfs_per_input: args.mfs.clone(),
        epochs: args.epochs,
        initial_step: args.step_size,
        selection: if checking.is_some() {
            ModelSelection::BestChecking
        } else {
            ModelSelection::BestTraining
        },
        ..TrainConfig::default()
    };
    let (model, report) = match &checking {
        Some(c) => train_with_checking(&data, c, &config)?,
        None => train(&data, &config)?,
    };
    model.save(&args.output)?;
    Ok(report)
}
