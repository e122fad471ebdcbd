//! The ANFIS model: its JSON form, validation, the forward pass and the error gradient.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::AnfisError;
use super::bell::{BellEval, BellGradient, BellMf};
use super::data::Dataset;

/// The `format` tag of a model file.
pub const MODEL_FORMAT: &str = "ugv-anfis";
/// The model file version this code reads and writes.
pub const MODEL_VERSION: u32 = 1;

/// The plain-data (JSON) form of a model; [`AnfisModel`] is its validated form.
///
/// ```json
/// { "format": "ugv-anfis", "version": 1,
///   "inputs": [ { "name": "x", "range": [-10.0, 10.0],
///                 "mfs": [ { "a": 0.33, "b": 2.0, "c": -1.0 }, ... ] }, ... ],
///   "output": "z",
///   "rules": [ { "antecedent": [0, 3], "p": [0.1, -0.2], "r": 0.5 }, ... ] }
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSpec {
    /// Always [`MODEL_FORMAT`].
    pub format: String,
    /// Always [`MODEL_VERSION`].
    pub version: u32,
    /// The input variables, in the order `predict` takes them.
    pub inputs: Vec<InputSpec>,
    /// Name of the output variable.
    pub output: String,
    /// The rules (a full grid when trained here, but any set is accepted).
    pub rules: Vec<RuleSpec>,
}

/// One input variable.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct InputSpec {
    /// Name (a data column name); non-empty and unique within the model.
    pub name: String,
    /// Normalisation range [lo, hi], lo < hi: lo maps to u = -1 and hi to u = +1.
    pub range: [f64; 2],
    /// The input's bell MFs, in normalised units.
    pub mfs: Vec<BellMf>,
}

/// One first-order Sugeno rule: if u_1 is MF antecedent[0] and ... then
/// f = p . u + r.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RuleSpec {
    /// Index of the MF of each input, one per input.
    pub antecedent: Vec<usize>,
    /// Linear coefficients, one per (normalised) input.
    pub p: Vec<f64>,
    /// Constant term.
    pub r: f64,
}

/// A validated first-order Sugeno ANFIS (see the module documentation for the
/// equations). Serialises as its [`ModelSpec`]; deserialising validates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "ModelSpec", into = "ModelSpec")]
pub struct AnfisModel {
    spec: ModelSpec,
}

impl TryFrom<ModelSpec> for AnfisModel {
    type Error = AnfisError;

    fn try_from(spec: ModelSpec) -> Result<Self, AnfisError> {
        AnfisModel::new(spec)
    }
}

impl From<AnfisModel> for ModelSpec {
    fn from(model: AnfisModel) -> Self {
        model.spec
    }
}

fn invalid(field: impl Into<String>, reason: impl Into<String>) -> AnfisError {
    AnfisError::InvalidModel {
        field: field.into(),
        reason: reason.into(),
    }
}

fn check_finite(field: impl Fn() -> String, value: f64) -> Result<(), AnfisError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(invalid(field(), format!("not a finite number ({value})")))
    }
}

/// Checks every invariant of a model, naming the first offending field.
fn validate(spec: &ModelSpec) -> Result<(), AnfisError> {
    if spec.format != MODEL_FORMAT {
        return Err(invalid(
            "format",
            format!("expected \"{MODEL_FORMAT}\", got \"{}\"", spec.format),
        ));
    }
    if spec.version != MODEL_VERSION {
        return Err(invalid(
            "version",
            format!(
                "unsupported version {} (this code reads {MODEL_VERSION})",
                spec.version
            ),
        ));
    }
    if spec.inputs.is_empty() {
        return Err(invalid("inputs", "at least one input is required"));
    }
    for (i, input) in spec.inputs.iter().enumerate() {
        validate_input(i, input, &spec.inputs[..i])?;
    }
    if spec.rules.is_empty() {
        return Err(invalid("rules", "at least one rule is required"));
    }
    for (r, rule) in spec.rules.iter().enumerate() {
        validate_rule(r, rule, &spec.inputs)?;
    }
    Ok(())
}

/// Input `i`: a name none of the `earlier` inputs has, a finite range with lo < hi,
/// and at least one valid MF.
fn validate_input(i: usize, input: &InputSpec, earlier: &[InputSpec]) -> Result<(), AnfisError> {
    if input.name.is_empty() {
        return Err(invalid(format!("inputs[{i}].name"), "must not be empty"));
    }
    if earlier.iter().any(|o| o.name == input.name) {
        return Err(invalid(
            format!("inputs[{i}].name"),
            format!("duplicate input name '{}'", input.name),
        ));
    }
    let [lo, hi] = input.range;
    check_finite(|| format!("inputs[{i}].range[0]"), lo)?;
    check_finite(|| format!("inputs[{i}].range[1]"), hi)?;
    if lo >= hi || !(hi - lo).is_finite() {
        return Err(invalid(
            format!("inputs[{i}].range"),
            format!("needs lo < hi with a finite span, got [{lo}, {hi}]"),
        ));
    }
    if input.mfs.is_empty() {
        return Err(invalid(
            format!("inputs[{i}].mfs"),
            "at least one MF is required",
        ));
    }
    for (j, mf) in input.mfs.iter().enumerate() {
        check_finite(|| format!("inputs[{i}].mfs[{j}].a"), mf.a)?;
        check_finite(|| format!("inputs[{i}].mfs[{j}].b"), mf.b)?;
        check_finite(|| format!("inputs[{i}].mfs[{j}].c"), mf.c)?;
        if mf.a <= 0.0 {
            return Err(invalid(
                format!("inputs[{i}].mfs[{j}].a"),
                format!("the width must be positive, got {}", mf.a),
            ));
        }
        if mf.b <= 0.0 {
            return Err(invalid(
                format!("inputs[{i}].mfs[{j}].b"),
                format!("the slope exponent must be positive, got {}", mf.b),
            ));
        }
    }
    Ok(())
}

/// Rule `r`: an MF of each input, and finite coefficients, one per input.
fn validate_rule(r: usize, rule: &RuleSpec, inputs: &[InputSpec]) -> Result<(), AnfisError> {
    let n = inputs.len();
    if rule.antecedent.len() != n {
        return Err(invalid(
            format!("rules[{r}].antecedent"),
            format!(
                "has {} entries, the model has {n} inputs",
                rule.antecedent.len()
            ),
        ));
    }
    for (i, (&m, input)) in rule.antecedent.iter().zip(inputs).enumerate() {
        if m >= input.mfs.len() {
            return Err(invalid(
                format!("rules[{r}].antecedent[{i}]"),
                format!(
                    "MF index {m} out of range: input '{}' has {} MFs",
                    input.name,
                    input.mfs.len()
                ),
            ));
        }
    }
    if rule.p.len() != n {
        return Err(invalid(
            format!("rules[{r}].p"),
            format!(
                "has {} coefficients, the model has {n} inputs",
                rule.p.len()
            ),
        ));
    }
    for (i, &p) in rule.p.iter().enumerate() {
        check_finite(|| format!("rules[{r}].p[{i}]"), p)?;
    }
    check_finite(|| format!("rules[{r}].r"), rule.r)
}

/// Scratch space of one forward pass (reused across rows while training).
#[derive(Debug)]
pub(crate) struct Workspace {
    /// Normalised inputs u.
    pub u: Vec<f64>,
    /// Every MF evaluated at its input: evals[i][j].
    pub evals: Vec<Vec<BellEval>>,
    /// Normalised firing strengths wbar_r.
    pub wbar: Vec<f64>,
    /// Rule outputs f_r.
    pub f: Vec<f64>,
}

impl Workspace {
    pub(crate) fn new(spec: &ModelSpec) -> Self {
        Workspace {
            u: vec![0.0; spec.inputs.len()],
            evals: spec
                .inputs
                .iter()
                .map(|inp| vec![BellEval::default(); inp.mfs.len()])
                .collect(),
            wbar: vec![0.0; spec.rules.len()],
            f: vec![0.0; spec.rules.len()],
        }
    }
}

impl AnfisModel {
    /// Validates a model: format and version, at least one input and one rule,
    /// unique non-empty input names, finite numbers, lo < hi, a > 0, b > 0, one
    /// antecedent index (in range) and one coefficient per input in every rule.
    pub fn new(spec: ModelSpec) -> Result<Self, AnfisError> {
        validate(&spec)?;
        Ok(AnfisModel { spec })
    }

    /// The model's parameters.
    pub fn spec(&self) -> &ModelSpec {
        &self.spec
    }

    /// Gives the parameters back (to edit them and validate again with [`AnfisModel::new`]).
    pub fn into_spec(self) -> ModelSpec {
        self.spec
    }

    /// Mutable access for the trainer, which keeps the invariants (a, b clamped).
    pub(crate) fn spec_mut(&mut self) -> &mut ModelSpec {
        &mut self.spec
    }

    /// Number of inputs.
    pub fn n_inputs(&self) -> usize {
        self.spec.inputs.len()
    }

    /// Number of rules.
    pub fn n_rules(&self) -> usize {
        self.spec.rules.len()
    }

    /// The input names, in `predict` order.
    pub fn input_names(&self) -> Vec<&str> {
        self.spec.inputs.iter().map(|i| i.name.as_str()).collect()
    }

    /// Check that the model takes the inputs named `expected`, in this order: a caller
    /// feeds inputs by position, so a model trained on other columns (or on these in
    /// another order) would compute a wrong output without any error. The refusal
    /// names the first input that differs.
    pub fn check_input_names(&self, expected: &[&str]) -> Result<(), AnfisError> {
        let found = self.input_names();
        let wanted = format!("({}), in this order", expected.join(", "));
        if found.len() != expected.len() {
            return Err(AnfisError::InvalidModel {
                field: "inputs".to_owned(),
                reason: format!(
                    "the model takes {} inputs ({}); they must be {wanted}",
                    found.len(),
                    found.join(", ")
                ),
            });
        }
        match found.iter().zip(expected).position(|(f, e)| f != e) {
            None => Ok(()),
            Some(i) => Err(AnfisError::InvalidModel {
                field: format!("inputs[{i}].name"),
                reason: format!(
                    "is {:?} where {:?} is fed; the inputs must be {wanted}",
                    found[i], expected[i]
                ),
            }),
        }
    }

    /// The output name.
    pub fn output_name(&self) -> &str {
        &self.spec.output
    }

    /// Parses and validates a model from JSON.
    pub fn from_json(text: &str) -> Result<Self, AnfisError> {
        let spec: ModelSpec = serde_json::from_str(text).map_err(|source| AnfisError::Json {
            what: "ANFIS model".into(),
            source,
        })?;
        AnfisModel::new(spec)
    }

    /// The model as pretty-printed JSON.
    pub fn to_json(&self) -> Result<String, AnfisError> {
        serde_json::to_string_pretty(&self.spec).map_err(|source| AnfisError::Json {
            what: "ANFIS model".into(),
            source,
        })
    }

    /// Reads and validates a model file; errors name the file.
    pub fn load(path: &Path) -> Result<Self, AnfisError> {
        let text = std::fs::read_to_string(path).map_err(|source| AnfisError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        AnfisModel::from_json(&text).map_err(|e| AnfisError::in_file(path, e))
    }

    /// Writes the model as JSON (to a sibling temporary file first, then renamed, so a
    /// reader never sees a half-written model).
    pub fn save(&self, path: &Path) -> Result<(), AnfisError> {
        let text = self.to_json()?;
        let io = |source| AnfisError::Io {
            path: path.to_path_buf(),
            source,
        };
        match path.file_name() {
            Some(name) => {
                let mut tmp_name = name.to_os_string();
                tmp_name.push(".tmp");
                let tmp = path.with_file_name(tmp_name);
                std::fs::write(&tmp, text).map_err(io)?;
                std::fs::rename(&tmp, path).map_err(io)
            }
            None => std::fs::write(path, text).map_err(io),
        }
    }

    /// Checks an input vector's length and values.
    fn check_input(&self, x: &[f64]) -> Result<(), AnfisError> {
        if x.len() != self.n_inputs() {
            return Err(AnfisError::InputLength {
                expected: self.n_inputs(),
                found: x.len(),
            });
        }
        if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(AnfisError::NonFiniteInput {
                index,
                name: self.spec.inputs[index].name.clone(),
                value,
            });
        }
        Ok(())
    }

    /// The model output o(x) for raw (not normalised) inputs in [`AnfisModel::input_names`]
    /// order. Errors on a wrong length, NaN or infinite inputs, or an overflowing result.
    pub fn predict(&self, x: &[f64]) -> Result<f64, AnfisError> {
        self.check_input(x)?;
        let mut ws = Workspace::new(&self.spec);
        self.forward(x, &mut ws)
    }

    /// The normalised firing strengths wbar_r (layer 3) at x, in rule order; they sum to 1.
    pub fn firing_strengths(&self, x: &[f64]) -> Result<Vec<f64>, AnfisError> {
        self.check_input(x)?;
        let mut ws = Workspace::new(&self.spec);
        self.forward(x, &mut ws)?;
        Ok(ws.wbar)
    }

    /// Maps raw inputs to normalised ones (u = -1 at lo, +1 at hi).
    pub(crate) fn normalise_into(&self, x: &[f64], u: &mut [f64]) {
        for ((u, &x), input) in u.iter_mut().zip(x).zip(&self.spec.inputs) {
            let [lo, hi] = input.range;
            *u = 2.0 * (x - lo) / (hi - lo) - 1.0;
        }
    }

    /// Forward pass for one row, whose length and finiteness the caller has checked.
    /// Fills the workspace and returns o.
    pub(crate) fn forward(&self, x: &[f64], ws: &mut Workspace) -> Result<f64, AnfisError> {
        self.normalise_into(x, &mut ws.u);
        for ((input, evals), &u) in self.spec.inputs.iter().zip(&mut ws.evals).zip(&ws.u) {
            for (mf, e) in input.mfs.iter().zip(evals.iter_mut()) {
                *e = mf.eval(u);
            }
        }
        // Layers 2-3 in the log domain: ln w_r, then a max-shifted softmax.
        let mut max_log = f64::NEG_INFINITY;
        for (rule, lw) in self.spec.rules.iter().zip(ws.wbar.iter_mut()) {
            *lw = rule
                .antecedent
                .iter()
                .zip(&ws.evals)
                .map(|(&m, evals)| evals[m].log_mu)
                .sum();
            max_log = max_log.max(*lw);
        }
        if !max_log.is_finite() {
            return Err(AnfisError::Numerical {
                reason: format!(
                    "no rule fires at normalised input {:?} (inputs or MF widths too extreme)",
                    ws.u
                ),
            });
        }
        let mut total = 0.0;
        for w in ws.wbar.iter_mut() {
            *w = (*w - max_log).exp();
            total += *w;
        }
        let mut o = 0.0;
        for ((rule, w), f) in self
            .spec
            .rules
            .iter()
            .zip(ws.wbar.iter_mut())
            .zip(&mut ws.f)
        {
            *w /= total;
            *f = rule.p.iter().zip(&ws.u).map(|(p, u)| p * u).sum::<f64>() + rule.r;
            o += *w * *f;
        }
        if o.is_finite() {
            Ok(o)
        } else {
            Err(AnfisError::Numerical {
                reason: format!("the output overflows at normalised input {:?}", ws.u),
            })
        }
    }

    fn check_data(&self, data: &Dataset) -> Result<(), AnfisError> {
        if data.n_inputs() != self.n_inputs() {
            return Err(AnfisError::InvalidData {
                reason: format!(
                    "the data has {} inputs, the model {}",
                    data.n_inputs(),
                    self.n_inputs()
                ),
            });
        }
        Ok(())
    }

    /// Root-mean-square error over a data set (same number of inputs as the model).
    pub fn rmse(&self, data: &Dataset) -> Result<f64, AnfisError> {
        self.check_data(data)?;
        let mut ws = Workspace::new(&self.spec);
        let mut sse = 0.0;
        for (x, t) in data.rows().zip(data.targets()) {
            let e = t - self.forward(x, &mut ws)?;
            sse += e * e;
        }
        Ok((sse / data.len() as f64).sqrt())
    }

    /// The squared error E = sum_p (t_p - o_p)^2 over a data set and its analytic
    /// gradient with respect to every premise parameter, `gradient[i][j]` for MF j of
    /// input i (in normalised units, consequents held fixed):
    ///
    /// ```text
    /// dE/dalpha_ij = sum_p -2 (t_p - o_p) * (sum_{r: m_r(i) = j} wbar_r (f_r - o_p))
    ///                                     * d ln mu_ij / dalpha_ij
    /// ```
    pub fn squared_error_gradient(
        &self,
        data: &Dataset,
    ) -> Result<(f64, Vec<Vec<BellGradient>>), AnfisError> {
        self.check_data(data)?;
        let mut ws = Workspace::new(&self.spec);
        let mut grad: Vec<Vec<BellGradient>> = self
            .spec
            .inputs
            .iter()
            .map(|inp| vec![BellGradient::default(); inp.mfs.len()])
            .collect();
        // do/dl_ij for the current row.
        let mut d_log: Vec<Vec<f64>> = self
            .spec
            .inputs
            .iter()
            .map(|inp| vec![0.0; inp.mfs.len()])
            .collect();
        let mut sse = 0.0;
        for (x, &t) in data.rows().zip(data.targets()) {
            let o = self.forward(x, &mut ws)?;
            let e = t - o;
            sse += e * e;
            for row in d_log.iter_mut() {
                row.fill(0.0);
            }
            for ((rule, &w), &f) in self.spec.rules.iter().zip(&ws.wbar).zip(&ws.f) {
                let coef = w * (f - o);
                for (&m, d) in rule.antecedent.iter().zip(d_log.iter_mut()) {
                    d[m] += coef;
                }
            }
            let d_e_d_o = -2.0 * e;
            for (((input, evals), d), g) in self
                .spec
                .inputs
                .iter()
                .zip(&ws.evals)
                .zip(&d_log)
                .zip(grad.iter_mut())
            {
                for (((mf, ev), &dl), g) in input.mfs.iter().zip(evals).zip(d).zip(g.iter_mut()) {
                    if dl == 0.0 {
                        continue;
                    }
                    let (da, db, dc) = mf.log_derivatives(ev);
                    let k = d_e_d_o * dl;
                    g.a += k * da;
                    g.b += k * db;
                    g.c += k * dc;
                }
            }
        }
        Ok((sse, grad))
    }
}
