//! Jang's hybrid learning: least squares for the consequents, gradient descent with
//! adaptive step size for the premises (see the module documentation).

use nalgebra::{DMatrix, DVector, SVD};
use serde::{Deserialize, Serialize};

use super::AnfisError;
use super::bell::BellMf;
use super::data::Dataset;
use super::model::{
    AnfisModel, InputSpec, MODEL_FORMAT, MODEL_VERSION, ModelSpec, RuleSpec, Workspace,
};

/// At most this many bell MFs on one input.
pub const MAX_MFS_PER_INPUT: usize = 32;

/// At most this many rules: the product of the inputs' MF counts (the full grid), so
/// `mfs^inputs` with one count for every input. Jang's examples have 16 to 81; the
/// consequent least squares grow with the square of the rules.
pub const MAX_RULES: usize = 1024;

/// At most this many epochs (a record of three numbers is kept per epoch).
pub const MAX_EPOCHS: usize = 100_000;

/// The largest initial step size k, normalised units (the inputs span [-1, 1], so a
/// longer step jumps across the whole input range).
pub const MAX_INITIAL_STEP: f64 = 1.0;

/// At most this many cells in the least-squares design matrix (data rows times rules
/// times inputs + 1): 2^26 cells, 512 MiB of f64.
pub const MAX_DESIGN_CELLS: usize = 1 << 26;

/// Which epoch's parameters [`train`] returns.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ModelSelection {
    /// The epoch with the lowest training RMSE.
    #[default]
    BestTraining,
    /// The epoch with the lowest checking RMSE (Jang's guard against over-fitting);
    /// the lowest training RMSE when there is no checking data.
    BestChecking,
    /// The last epoch.
    LastEpoch,
}

/// Training configuration; `Default` holds the defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainConfig {
    /// Bell MFs per input (each 1 to [`MAX_MFS_PER_INPUT`]); one entry applies to every
    /// input. The rule grid has their product of rules, at most [`MAX_RULES`].
    pub mfs_per_input: Vec<usize>,
    /// Epochs (1 to [`MAX_EPOCHS`]). Epoch 0 is least squares on the initial MFs.
    pub epochs: usize,
    /// Jang's initial step size k (0 < k <= [`MAX_INITIAL_STEP`]): the length of each
    /// premise update in the parameter space of normalised units (inputs span [-1, 1]).
    pub initial_step: f64,
    /// Factor applied to k after four consecutive error decreases (Jang: 1.1).
    pub step_increase: f64,
    /// Factor applied to k after two increase/decrease alternations (Jang: 0.9).
    pub step_decrease: f64,
    /// Smallest MF half width a (> 0), normalised units; updates are clamped to it.
    pub min_width: f64,
    /// Smallest MF slope exponent b (> 0); updates are clamped to it.
    pub min_shape: f64,
    /// Stop once the training RMSE is at or below this (0: run every epoch).
    pub error_goal: f64,
    /// Normalisation ranges [lo, hi] per input; the training data's min and max when
    /// absent.
    pub input_ranges: Option<Vec<[f64; 2]>>,
    /// Which epoch's parameters to return.
    pub selection: ModelSelection,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            mfs_per_input: vec![3],
            epochs: 100,
            initial_step: 0.01,
            step_increase: 1.1,
            step_decrease: 0.9,
            min_width: 1e-3,
            min_shape: 1e-2,
            error_goal: 0.0,
            input_ranges: None,
            selection: ModelSelection::BestTraining,
        }
    }
}

/// What happened during training.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainReport {
    /// Training RMSE of every epoch, after that epoch's least-squares step (index 0:
    /// least squares on the initial MFs, before any premise update).
    pub training_rmse: Vec<f64>,
    /// Checking RMSE of every epoch, when checking data was given.
    pub checking_rmse: Option<Vec<f64>>,
    /// Step size k used for each epoch's premise update (after that epoch's
    /// adaptation).
    pub step_sizes: Vec<f64>,
    /// The epoch whose parameters were returned.
    pub best_epoch: usize,
    /// Number of rules.
    pub rules: usize,
    /// Number of premise parameters (3 per MF).
    pub premise_parameters: usize,
    /// Number of consequent parameters (N + 1 per rule).
    pub consequent_parameters: usize,
}

impl TrainReport {
    /// Training RMSE of the returned model.
    pub fn final_training_rmse(&self) -> f64 {
        self.training_rmse
            .get(self.best_epoch)
            .copied()
            .unwrap_or(f64::NAN)
    }

    /// Checking RMSE of the returned model, when checking data was given.
    pub fn final_checking_rmse(&self) -> Option<f64> {
        self.checking_rmse
            .as_ref()
            .and_then(|c| c.get(self.best_epoch).copied())
    }
}

fn config_err(field: &str, reason: impl Into<String>) -> AnfisError {
    AnfisError::InvalidConfig {
        field: field.into(),
        reason: reason.into(),
    }
}

fn positive(field: &str, value: f64) -> Result<(), AnfisError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(config_err(
            field,
            format!("must be a positive finite number, got {value}"),
        ))
    }
}

/// MF counts within 1..=[`MAX_MFS_PER_INPUT`] whose grid has at most [`MAX_RULES`]
/// rules; returns the rule count.
pub(super) fn check_grid(field: &str, mfs: &[usize]) -> Result<usize, AnfisError> {
    if let Some((i, m)) = mfs
        .iter()
        .enumerate()
        .find(|(_, m)| !(1..=MAX_MFS_PER_INPUT).contains(*m))
    {
        return Err(config_err(
            field,
            format!("input {i} has {m} MFs; each input takes 1 to {MAX_MFS_PER_INPUT}"),
        ));
    }
    match mfs.iter().try_fold(1usize, |acc, &m| acc.checked_mul(m)) {
        Some(rules) if rules <= MAX_RULES => Ok(rules),
        rules => Err(config_err(
            field,
            format!(
                "{} MFs over {} inputs make {} rules (their product); at most {MAX_RULES}",
                mfs.iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(" x "),
                mfs.len(),
                rules.map_or_else(|| "more than 2^64".to_owned(), |r| r.to_string()),
            ),
        )),
    }
}

/// Epochs within 1..=[`MAX_EPOCHS`].
pub(super) fn check_epochs(field: &str, epochs: usize) -> Result<(), AnfisError> {
    if (1..=MAX_EPOCHS).contains(&epochs) {
        Ok(())
    } else {
        Err(config_err(
            field,
            format!("{epochs} epochs; give 1 to {MAX_EPOCHS}"),
        ))
    }
}

/// An initial step within (0, [`MAX_INITIAL_STEP`]].
pub(super) fn check_step(field: &str, step: f64) -> Result<(), AnfisError> {
    positive(field, step)?;
    if step <= MAX_INITIAL_STEP {
        Ok(())
    } else {
        Err(config_err(
            field,
            format!(
                "{step:e} is more than {MAX_INITIAL_STEP} (normalised units; inputs span [-1, 1])"
            ),
        ))
    }
}

impl TrainConfig {
    /// Checks the configuration for `n_inputs` inputs and returns the MF count of each.
    fn validate(&self, n_inputs: usize) -> Result<Vec<usize>, AnfisError> {
        let mfs = match self.mfs_per_input.as_slice() {
            [m] => vec![*m; n_inputs],
            list if list.len() == n_inputs => list.to_vec(),
            list => {
                return Err(config_err(
                    "mfs_per_input",
                    format!(
                        "{} entries for {n_inputs} inputs (give one, or one per input)",
                        list.len()
                    ),
                ));
            }
        };
        if let Some(i) = mfs.iter().position(|&m| m == 0) {
            return Err(config_err("mfs_per_input", format!("input {i} has 0 MFs")));
        }
        check_grid("mfs_per_input", &mfs)?;
        check_epochs("epochs", self.epochs)?;
        check_step("initial_step", self.initial_step)?;
        positive("step_increase", self.step_increase)?;
        positive("step_decrease", self.step_decrease)?;
        positive("min_width", self.min_width)?;
        positive("min_shape", self.min_shape)?;
        if !(self.error_goal.is_finite() && self.error_goal >= 0.0) {
            return Err(config_err(
                "error_goal",
                format!("must be a finite number >= 0, got {}", self.error_goal),
            ));
        }
        if let Some(ranges) = &self.input_ranges {
            if ranges.len() != n_inputs {
                return Err(config_err(
                    "input_ranges",
                    format!("{} ranges for {n_inputs} inputs", ranges.len()),
                ));
            }
            for (i, &[lo, hi]) in ranges.iter().enumerate() {
                if !(lo.is_finite() && hi.is_finite() && lo < hi && (hi - lo).is_finite()) {
                    return Err(config_err(
                        "input_ranges",
                        format!("input {i}: needs finite lo < hi, got [{lo}, {hi}]"),
                    ));
                }
            }
        }
        Ok(mfs)
    }
}

/// Jang's initial MFs for one input: m centres evenly spaced over [-1, 1], a half the
/// spacing, b = 2 (neighbours cross at 0.5); one MF: c = 0, a = 1.
fn initial_mfs(m: usize) -> Vec<BellMf> {
    if m == 1 {
        return vec![BellMf {
            a: 1.0,
            b: 2.0,
            c: 0.0,
        }];
    }
    let spacing = 2.0 / (m - 1) as f64;
    (0..m)
        .map(|j| BellMf {
            a: spacing / 2.0,
            b: 2.0,
            c: -1.0 + spacing * j as f64,
        })
        .collect()
}

/// The full rule grid, the last input's MF index varying fastest, zero consequents.
fn grid_rules(mfs: &[usize]) -> Result<Vec<RuleSpec>, AnfisError> {
    let total = mfs
        .iter()
        .try_fold(1usize, |acc, &m| acc.checked_mul(m))
        .ok_or_else(|| config_err("mfs_per_input", "the rule grid overflows usize"))?;
    let n = mfs.len();
    let mut rules = Vec::with_capacity(total);
    let mut index = vec![0usize; n];
    for _ in 0..total {
        rules.push(RuleSpec {
            antecedent: index.clone(),
            p: vec![0.0; n],
            r: 0.0,
        });
        for i in (0..n).rev() {
            index[i] += 1;
            if index[i] < mfs[i] {
                break;
            }
            index[i] = 0;
        }
    }
    Ok(rules)
}

/// Jang's step-size adaptation over the error history of the epochs so far.
#[derive(Debug)]
struct StepSize {
    k: f64,
    increase: f64,
    decrease: f64,
    last_increase: Option<usize>,
    last_decrease: Option<usize>,
}

impl StepSize {
    /// Adapts k after the error of epoch `errors.len() - 1` has been recorded:
    /// four consecutive decreases multiply it by `increase`; four changes alternating
    /// in sign (two increase/decrease combinations) by `decrease`. A rule fires again
    /// only after four more epochs.
    fn update(&mut self, errors: &[f64]) {
        let Some(e) = errors.len().checked_sub(1) else {
            return;
        };
        if e < 4 {
            return;
        }
        let d: Vec<f64> = errors[e - 4..=e].windows(2).map(|w| w[1] - w[0]).collect();
        let ready = |last: Option<usize>| last.is_none_or(|l| e - l >= 4);
        if d.iter().all(|&x| x < 0.0) && ready(self.last_increase) {
            self.k *= self.increase;
            self.last_increase = Some(e);
        }
        let alternating = d.windows(2).all(|w| w[0] * w[1] < 0.0);
        if alternating && ready(self.last_decrease) {
            self.k *= self.decrease;
            self.last_decrease = Some(e);
        }
    }
}

/// Consequent parameters by least squares, min |A theta - t|^2, through an SVD with
/// singular values below `sigma_max * max(rows, cols) * eps` treated as zero
/// (minimum-norm solution when A is rank deficient).
fn least_squares(a: &DMatrix<f64>, t: &DVector<f64>) -> Result<DVector<f64>, AnfisError> {
    let (rows, cols) = a.shape();
    let max_iterations = 200 * rows.max(cols).max(100);
    let svd = SVD::try_new(a.clone(), true, true, 5.0 * f64::EPSILON, max_iterations).ok_or_else(
        || AnfisError::Numerical {
            reason: format!("the least-squares SVD ({rows} x {cols}) did not converge"),
        },
    )?;
    let sigma_max = svd.singular_values.max();
    let tolerance = sigma_max * rows.max(cols) as f64 * f64::EPSILON;
    svd.solve(t, tolerance)
        .map_err(|reason| AnfisError::Numerical {
            reason: format!("least squares: {reason}"),
        })
}

/// Trains a first-order Sugeno ANFIS on `data` with Jang's hybrid rule (see the
/// module documentation). Returns the selected model and the per-epoch report.
pub fn train(
    data: &Dataset,
    config: &TrainConfig,
) -> Result<(AnfisModel, TrainReport), AnfisError> {
    train_impl(data, None, config)
}

/// As [`train`], also reporting the RMSE on checking data each epoch (and selecting
/// on it with [`ModelSelection::BestChecking`]).
pub fn train_with_checking(
    data: &Dataset,
    checking: &Dataset,
    config: &TrainConfig,
) -> Result<(AnfisModel, TrainReport), AnfisError> {
    train_impl(data, Some(checking), config)
}

fn train_impl(
    data: &Dataset,
    checking: Option<&Dataset>,
    config: &TrainConfig,
) -> Result<(AnfisModel, TrainReport), AnfisError> {
    let n = data.n_inputs();
    let mfs = config.validate(n)?;
    if let Some(c) = checking
        && c.n_inputs() != n
    {
        return Err(AnfisError::InvalidData {
            reason: format!(
                "the checking data has {} inputs, the training data {n}",
                c.n_inputs()
            ),
        });
    }
    let mut model = initial_model(data, config, &mfs)?;
    let rules = model.n_rules();
    let cols = consequent_columns(data, rules, n + 1)?;
    let targets = DVector::from_column_slice(data.targets());
    let mut design = DMatrix::<f64>::zeros(data.len(), cols);
    let mut ws = Workspace::new(model.spec());
    let mut step = StepSize {
        k: config.initial_step,
        increase: config.step_increase,
        decrease: config.step_decrease,
        last_increase: None,
        last_decrease: None,
    };
    let mut report = TrainReport {
        training_rmse: Vec::with_capacity(config.epochs),
        checking_rmse: checking.map(|_| Vec::with_capacity(config.epochs)),
        step_sizes: Vec::with_capacity(config.epochs),
        best_epoch: 0,
        rules,
        premise_parameters: 3 * mfs.iter().sum::<usize>(),
        consequent_parameters: cols,
    };
    let mut best: Option<(f64, AnfisModel)> = None;

    for epoch in 0..config.epochs {
        let theta = fit_consequents(&mut model, data, &mut ws, &mut design, &targets, epoch)?;
        let residual = &design * &theta - &targets;
        let training = (residual.norm_squared() / data.len() as f64).sqrt();
        report.training_rmse.push(training);
        let checking_rmse = match checking {
            Some(c) => {
                let e = model.rmse(c)?;
                if let Some(list) = report.checking_rmse.as_mut() {
                    list.push(e);
                }
                Some(e)
            }
            None => None,
        };
        step.update(&report.training_rmse);
        report.step_sizes.push(step.k);

        let score = match config.selection {
            ModelSelection::BestTraining => training,
            ModelSelection::BestChecking => checking_rmse.unwrap_or(training),
            // Every epoch ties, and ties go to the later epoch.
            ModelSelection::LastEpoch => 0.0,
        };
        if best.as_ref().is_none_or(|(s, _)| score <= *s) {
            best = Some((score, model.clone()));
            report.best_epoch = epoch;
        }
        if training <= config.error_goal || epoch + 1 == config.epochs {
            break;
        }
        descend_premises(&mut model, data, step.k, config)?;
    }
    let model = best.map(|(_, m)| m).unwrap_or(model);
    Ok((model, report))
}

/// The untrained model: each input's range (the configured ones, or the data's) split
/// by its initial MFs, and the full grid of rules.
fn initial_model(
    data: &Dataset,
    config: &TrainConfig,
    mfs: &[usize],
) -> Result<AnfisModel, AnfisError> {
    let ranges = config
        .input_ranges
        .clone()
        .unwrap_or_else(|| data.input_ranges());
    for (name, &[lo, hi]) in data.input_names().iter().zip(&ranges) {
        if lo >= hi {
            return Err(AnfisError::DegenerateRange {
                name: name.clone(),
                lo,
                hi,
            });
        }
    }
    let inputs = data
        .input_names()
        .iter()
        .zip(&ranges)
        .zip(mfs)
        .map(|((name, &range), &m)| InputSpec {
            name: name.clone(),
            range,
            mfs: initial_mfs(m),
        })
        .collect();
    AnfisModel::new(ModelSpec {
        format: MODEL_FORMAT.into(),
        version: MODEL_VERSION,
        inputs,
        output: data.target_name().to_string(),
        rules: grid_rules(mfs)?,
    })
}

/// The design matrix's columns, `rules` times `width` (the inputs + 1), refused when
/// the matrix would exceed [`MAX_DESIGN_CELLS`].
fn consequent_columns(data: &Dataset, rules: usize, width: usize) -> Result<usize, AnfisError> {
    let cols = rules
        .checked_mul(width)
        .ok_or_else(|| config_err("mfs_per_input", "too many consequent parameters"))?;
    if data
        .len()
        .checked_mul(cols)
        .is_none_or(|cells| cells > MAX_DESIGN_CELLS)
    {
        return Err(config_err(
            "mfs_per_input",
            format!(
                "{} data rows x {cols} consequent parameters ({rules} rules x {width}) exceed the least squares' bound of {MAX_DESIGN_CELLS} cells: use fewer MFs or fewer rows",
                data.len()
            ),
        ));
    }
    Ok(cols)
}

/// The forward pass, premises fixed: fills the design matrix (row p is
/// [wbar_r u_p, wbar_r] per rule), solves the consequents by least squares and sets
/// them in the model. Returns them (theta).
fn fit_consequents(
    model: &mut AnfisModel,
    data: &Dataset,
    ws: &mut Workspace,
    design: &mut DMatrix<f64>,
    targets: &DVector<f64>,
    epoch: usize,
) -> Result<DVector<f64>, AnfisError> {
    let n = data.n_inputs();
    let width = n + 1;
    for (p, x) in data.rows().enumerate() {
        model.forward(x, ws)?;
        for (r, &w) in ws.wbar.iter().enumerate() {
            for (i, &u) in ws.u.iter().enumerate() {
                design[(p, r * width + i)] = w * u;
            }
            design[(p, r * width + n)] = w;
        }
    }
    let theta = least_squares(design, targets)?;
    for (r, rule) in model.spec_mut().rules.iter_mut().enumerate() {
        for (i, p) in rule.p.iter_mut().enumerate() {
            *p = theta[r * width + i];
        }
        rule.r = theta[r * width + n];
    }
    if theta.iter().any(|v| !v.is_finite()) {
        return Err(AnfisError::Numerical {
            reason: format!("epoch {epoch}: non-finite consequent parameters"),
        });
    }
    Ok(theta)
}

/// The backward pass, consequents fixed: a step of length `k` against the gradient
/// of the premises (none when the gradient is zero or not finite), widths and shapes
/// kept at their minimums.
fn descend_premises(
    model: &mut AnfisModel,
    data: &Dataset,
    k: f64,
    config: &TrainConfig,
) -> Result<(), AnfisError> {
    let (_, grad) = model.squared_error_gradient(data)?;
    let norm = grad
        .iter()
        .flatten()
        .map(|g| g.a * g.a + g.b * g.b + g.c * g.c)
        .sum::<f64>()
        .sqrt();
    if !(norm.is_finite() && norm > 0.0) {
        return Ok(());
    }
    let eta = k / norm;
    for (input, g) in model.spec_mut().inputs.iter_mut().zip(&grad) {
        for (mf, g) in input.mfs.iter_mut().zip(g) {
            mf.a = (mf.a - eta * g.a).max(config.min_width);
            mf.b = (mf.b - eta * g.b).max(config.min_shape);
            mf.c -= eta * g.c;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stepper() -> StepSize {
        StepSize {
            k: 1.0,
            increase: 1.1,
            decrease: 0.9,
            last_increase: None,
            last_decrease: None,
        }
    }

    fn run(errors: &[f64]) -> Vec<f64> {
        let mut s = stepper();
        (1..=errors.len())
            .map(|e| {
                s.update(&errors[..e]);
                s.k
            })
            .collect()
    }

    #[test]
    fn four_consecutive_decreases_grow_the_step_once_per_four_epochs() {
        let errors: Vec<f64> = (0..10).map(|e| 1.0 / f64::from(e + 1)).collect();
        let k = run(&errors);
        // Four decreases are first seen at epoch 4, then again at epoch 8.
        let expected = [1.0, 1.0, 1.0, 1.0, 1.1, 1.1, 1.1, 1.1, 1.21, 1.21];
        for (got, want) in k.iter().zip(expected) {
            assert!((got - want).abs() < 1e-12, "{k:?}");
        }
    }

    #[test]
    fn two_up_down_alternations_shrink_the_step() {
        let k = run(&[1.0, 0.9, 1.0, 0.8, 0.85]);
        assert!((k[4] - 0.9).abs() < 1e-12, "{k:?}");
        let k = run(&[1.0, 1.1, 1.0, 1.05, 0.9]);
        assert!((k[4] - 0.9).abs() < 1e-12, "{k:?}");
        // Mixed patterns change nothing.
        let k = run(&[1.0, 0.9, 0.8, 0.85, 0.7, 0.6]);
        assert!(k.iter().all(|&v| v == 1.0), "{k:?}");
    }

    #[test]
    fn the_grid_enumerates_every_rule_once_last_input_fastest() {
        let rules = grid_rules(&[2, 3]).unwrap_or_default();
        let antecedents: Vec<Vec<usize>> = rules.into_iter().map(|r| r.antecedent).collect();
        assert_eq!(
            antecedents,
            vec![
                vec![0, 0],
                vec![0, 1],
                vec![0, 2],
                vec![1, 0],
                vec![1, 1],
                vec![1, 2]
            ]
        );
    }

    #[test]
    fn initial_mfs_cross_at_one_half() {
        let mfs = initial_mfs(4);
        assert_eq!(mfs.len(), 4);
        assert!((mfs[0].c + 1.0).abs() < 1e-15 && (mfs[3].c - 1.0).abs() < 1e-15);
        for w in mfs.windows(2) {
            let mid = 0.5 * (w[0].c + w[1].c);
            assert!((w[0].grade(mid) - 0.5).abs() < 1e-12);
            assert!((w[1].grade(mid) - 0.5).abs() < 1e-12);
        }
    }
}
