//! Integration tests of the ANFIS learner (controller::anfis).
//!
//! Errors and gradients are recomputed here from `predict` alone (independently of the
//! trainer's least-squares residual and analytic derivatives); thresholds are justified
//! next to each assertion from measurements of this implementation.
//!
//! Everything sits in `mod anfis` so that `cargo test -p ugv-controller anfis` selects
//! these tests by name.

mod anfis {
    use std::f64::consts::PI;
    use std::path::PathBuf;
    use std::sync::OnceLock;

    use anyhow::{Context, Result, anyhow, bail, ensure};
    use proptest::prelude::*;
    use ugv_controller::anfis::{
        AnfisError, AnfisModel, BellMf, DataFormat, Dataset, InputSpec, MODEL_FORMAT,
        MODEL_VERSION, ModelSelection, ModelSpec, RuleSpec, TrainArgs, TrainConfig, TrainReport,
        train, train_command, train_with_checking,
    };

    // ---------------------------------------------------------------- helpers

    fn sinc(v: f64) -> f64 {
        if v == 0.0 { 1.0 } else { v.sin() / v }
    }

    /// n evenly spaced points from lo to hi, both included.
    fn linspace(n: usize, lo: f64, hi: f64) -> Vec<f64> {
        (0..n)
            .map(|k| lo + (hi - lo) * k as f64 / (n - 1) as f64)
            .collect()
    }

    fn names(list: &[&str]) -> Vec<String> {
        list.iter().map(|s| s.to_string()).collect()
    }

    /// z = sinc(x) sinc(y) on the grid xs x xs.
    fn sinc_data(xs: &[f64]) -> Result<Dataset> {
        let mut rows = Vec::new();
        let mut targets = Vec::new();
        for &x in xs {
            for &y in xs {
                rows.push(vec![x, y]);
                targets.push(sinc(x) * sinc(y));
            }
        }
        Ok(Dataset::new(names(&["x", "y"]), "z".into(), rows, targets)?)
    }

    /// RMSE of a model over a data set, through `predict` only.
    fn rmse_by_predict(model: &AnfisModel, data: &Dataset) -> Result<f64> {
        let mut sse = 0.0;
        for (x, t) in data.rows().zip(data.targets()) {
            let e = t - model.predict(x)?;
            sse += e * e;
        }
        Ok((sse / data.len() as f64).sqrt())
    }

    /// A unique path in the system temp directory for this test process.
    fn temp_path(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("ugv-anfis-test-{}-{name}", std::process::id()))
    }

    /// Jang's two-input sinc benchmark, trained once for the tests that share it:
    /// 121 training points on the 11 x 11 grid over [-10, 10]^2, 4 MFs per input (16
    /// rules), 250 epochs, initial step 0.1 (normalised units), checking data on the
    /// 10 x 10 grid of cell midpoints (-9, -7, ..., 9), never seen in training.
    struct Sinc {
        model: AnfisModel,
        report: TrainReport,
        training: Dataset,
        checking: Dataset,
    }

    const SINC_EPOCHS: usize = 250;

    fn sinc_benchmark() -> Result<&'static Sinc> {
        static SINC: OnceLock<Result<Sinc, String>> = OnceLock::new();
        SINC.get_or_init(|| {
            let run = || -> Result<Sinc> {
                let training = sinc_data(&linspace(11, -10.0, 10.0))?;
                let checking = sinc_data(&linspace(10, -9.0, 9.0))?;
                let config = TrainConfig {
                    mfs_per_input: vec![4],
                    epochs: SINC_EPOCHS,
                    initial_step: 0.1,
                    ..TrainConfig::default()
                };
                let (model, report) = train_with_checking(&training, &checking, &config)?;
                Ok(Sinc {
                    model,
                    report,
                    training,
                    checking,
                })
            };
            run().map_err(|e| format!("{e:#}"))
        })
        .as_ref()
        .map_err(|e| anyhow!("sinc training failed: {e}"))
    }

    // ---------------------------------------------------------------- Jang's sinc benchmark

    #[test]
    fn sinc_benchmark_training_rmse_below_0_01_after_250_epochs() -> Result<()> {
        let s = sinc_benchmark()?;
        let r = &s.report;
        ensure!(r.rules == 16 && r.premise_parameters == 24 && r.consequent_parameters == 48);
        ensure!(r.training_rmse.len() == SINC_EPOCHS && r.step_sizes.len() == SINC_EPOCHS);
        let lse_only = r.training_rmse[0];
        let trained = rmse_by_predict(&s.model, &s.training)?;
        eprintln!(
            "sinc: LSE-only {lse_only:.4e}, after {SINC_EPOCHS} epochs {trained:.4e} (best epoch {}), final step {:.4e}",
            r.best_epoch,
            r.step_sizes.last().copied().unwrap_or(f64::NAN)
        );
        // The trainer's residual-based RMSE and the one recomputed through predict agree.
        ensure!(
            (trained - r.final_training_rmse()).abs() < 1e-12,
            "predict gives {trained}, the report {}",
            r.final_training_rmse()
        );
        // Measured (x86-64, this code): 0.1050 after the LSE-only epoch 0, 0.0065 after
        // 250 epochs. 0.01 leaves a 1.5x margin for other platforms' libm; a premise
        // learner that does nothing useful stays near 0.1.
        ensure!(
            trained < 0.01,
            "training RMSE {trained} after {SINC_EPOCHS} epochs"
        );
        // Gradient descent on the premises must improve on least squares alone (measured
        // ratio 0.06; 0.25 is a loose bound).
        ensure!(
            trained < 0.25 * lse_only,
            "training RMSE {trained} vs {lse_only} for LSE on the initial MFs"
        );
        Ok(())
    }

    #[test]
    fn sinc_benchmark_checking_rmse_on_off_grid_midpoints() -> Result<()> {
        let s = sinc_benchmark()?;
        let checking = rmse_by_predict(&s.model, &s.checking)?;
        let reported = s
            .report
            .final_checking_rmse()
            .context("checking RMSE missing from the report")?;
        ensure!(
            (checking - reported).abs() < 1e-12,
            "{checking} vs {reported}"
        );
        let initial = s
            .report
            .checking_rmse
            .as_ref()
            .and_then(|c| c.first().copied())
            .context("no checking RMSE for epoch 0")?;
        eprintln!(
            "sinc: checking RMSE on the 10 x 10 midpoints {initial:.4e} at epoch 0, {checking:.4e} returned"
        );
        // Measured: 0.114 at epoch 0, 0.046 after 250 epochs. The midpoints sit between
        // training samples 2 apart on a function that oscillates with period 2 pi, and the
        // 72 parameters are fitted to 121 points, so the checking error stays ~7x the
        // training error; 0.08 is the looser bound, and learning must still help.
        ensure!(checking < 0.08, "checking RMSE {checking}");
        ensure!(
            checking < initial,
            "checking RMSE {checking} vs {initial} at epoch 0"
        );
        Ok(())
    }

    // ---------------------------------------------------------------- gradient

    /// E = sum (t - o)^2 through predict only.
    fn sse(spec: &ModelSpec, data: &Dataset) -> Result<f64> {
        let model = AnfisModel::new(spec.clone())?;
        let r = rmse_by_predict(&model, data)?;
        Ok(r * r * data.len() as f64)
    }

    fn check_gradient_against_central_differences(data: &Dataset, mfs: Vec<usize>) -> Result<()> {
        let config = TrainConfig {
            mfs_per_input: mfs,
            epochs: 1,
            ..TrainConfig::default()
        };
        let (model, _) = train(data, &config)?;
        // Move the MFs off Jang's symmetric start so no derivative vanishes by symmetry.
        let mut spec = model.into_spec();
        for (i, input) in spec.inputs.iter_mut().enumerate() {
            for (j, mf) in input.mfs.iter_mut().enumerate() {
                let s = (i * 7 + j * 3) as f64;
                mf.a *= 1.0 + 0.13 * (s * 0.7).sin();
                mf.b += 0.4 * (s * 1.3).cos();
                mf.c += 0.05 * (s * 2.1).sin();
            }
        }
        let model = AnfisModel::new(spec.clone())?;
        let (e, grad) = model.squared_error_gradient(data)?;
        ensure!((e - sse(&spec, data)?).abs() < 1e-9 * (1.0 + e));
        let h = 1e-6;
        let mut checked = 0;
        for (i, g_input) in grad.iter().enumerate() {
            for (j, g) in g_input.iter().enumerate() {
                for (name, analytic) in [("a", g.a), ("b", g.b), ("c", g.c)] {
                    let shifted = |delta: f64| -> Result<f64> {
                        let mut s = spec.clone();
                        let mf = &mut s.inputs[i].mfs[j];
                        match name {
                            "a" => mf.a += delta,
                            "b" => mf.b += delta,
                            _ => mf.c += delta,
                        }
                        sse(&s, data)
                    };
                    let fd = (shifted(h)? - shifted(-h)?) / (2.0 * h);
                    // Central differences are accurate to O(h^2) plus rounding
                    // ~ eps * E / h; 1e-5 relative to max(|g|, 1e-3 E) covers both.
                    let scale = analytic.abs().max(1e-3 * e).max(1e-12);
                    ensure!(
                        (analytic - fd).abs() < 1e-5 * scale,
                        "input {i} MF {j} d/d{name}: analytic {analytic}, finite difference {fd}"
                    );
                    checked += 1;
                }
            }
        }
        // Every premise parameter was checked (the gradient has the model's shape).
        ensure!(checked == 3 * spec.inputs.iter().map(|i| i.mfs.len()).sum::<usize>());
        Ok(())
    }

    #[test]
    fn premise_gradient_matches_central_differences_two_inputs() -> Result<()> {
        let data = sinc_data(&linspace(9, -10.0, 10.0))?;
        check_gradient_against_central_differences(&data, vec![3, 4])
    }

    #[test]
    fn premise_gradient_matches_central_differences_three_inputs() -> Result<()> {
        let xs = linspace(5, -1.0, 2.0);
        let mut rows = Vec::new();
        let mut targets = Vec::new();
        for &x in &xs {
            for &y in &xs {
                for &z in &xs {
                    rows.push(vec![x, y, z]);
                    targets.push((x * y).sin() + z * z - 0.5 * x);
                }
            }
        }
        let data = Dataset::new(names(&["x", "y", "z"]), "t".into(), rows, targets)?;
        check_gradient_against_central_differences(&data, vec![2, 3, 2])
    }

    // ---------------------------------------------------------------- least squares

    #[test]
    fn lse_alone_fits_a_linear_target_exactly() -> Result<()> {
        // t = 3 x - 2 y + 0.25 z + 0.5 is representable by every rule having the same
        // (de-normalised) consequent, so least squares on any premises leaves no residual.
        let mut rows = Vec::new();
        let mut targets = Vec::new();
        for k in 0..60 {
            let k = f64::from(k);
            let (x, y, z) = (
                (k * 0.37).sin() * 4.0,
                (k * 0.91).cos() * 2.0 + 1.0,
                k * 0.1,
            );
            rows.push(vec![x, y, z]);
            targets.push(3.0 * x - 2.0 * y + 0.25 * z + 0.5);
        }
        let data = Dataset::new(names(&["x", "y", "z"]), "t".into(), rows, targets)?;
        let config = TrainConfig {
            mfs_per_input: vec![2, 3, 2],
            epochs: 1,
            ..TrainConfig::default()
        };
        let (model, report) = train(&data, &config)?;
        ensure!(report.training_rmse.len() == 1 && model.n_rules() == 12);
        // Targets are O(10): 1e-10 is rounding level for a 60 x 48 least-squares problem.
        let rmse = rmse_by_predict(&model, &data)?;
        ensure!(rmse < 1e-10, "RMSE {rmse} on a linear target");
        // It also extrapolates the plane exactly, away from the data.
        let off = model.predict(&[-7.0, 5.0, 20.0])?;
        let want = 3.0 * -7.0 - 2.0 * 5.0 + 0.25 * 20.0 + 0.5;
        ensure!((off - want).abs() < 1e-8, "{off} vs {want}");
        Ok(())
    }

    // ---------------------------------------------------------------- one input

    #[test]
    fn single_input_learns_sin() -> Result<()> {
        let xs = linspace(41, 0.0, 2.0 * PI);
        let data = Dataset::new(
            names(&["x"]),
            "y".into(),
            xs.iter().map(|&x| vec![x]).collect(),
            xs.iter().map(|x| x.sin()).collect(),
        )?;
        let mids: Vec<f64> = xs.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect();
        let checking = Dataset::new(
            names(&["x"]),
            "y".into(),
            mids.iter().map(|&x| vec![x]).collect(),
            mids.iter().map(|x| x.sin()).collect(),
        )?;
        let config = TrainConfig {
            mfs_per_input: vec![4],
            epochs: 200,
            ..TrainConfig::default()
        };
        let (model, report) = train_with_checking(&data, &checking, &config)?;
        let trained = rmse_by_predict(&model, &data)?;
        let checked = rmse_by_predict(&model, &checking)?;
        eprintln!(
            "sin(x): LSE-only {:.3e}, after {} epochs training {trained:.3e}, checking {checked:.3e}",
            report.training_rmse[0],
            report.training_rmse.len()
        );
        // Measured (x86-64): LSE-only 3.8e-2; after 200 epochs training 6.1e-4 and
        // checking 5.6e-4 (sin is smooth at this sampling, so checking tracks
        // training). Bounds 1.5e-3 leave a 2.5x margin and sit 25x below LSE alone.
        ensure!(trained < 1.5e-3, "training RMSE {trained}");
        ensure!(checked < 1.5e-3, "checking RMSE {checked}");
        ensure!(
            trained < report.training_rmse[0],
            "no improvement over LSE alone"
        );
        ensure!((model.predict(&[PI / 2.0])? - 1.0).abs() < 5e-3);
        Ok(())
    }

    // ---------------------------------------------------------------- model files

    fn small_trained_model() -> Result<AnfisModel> {
        let data = sinc_data(&linspace(7, -5.0, 5.0))?;
        let config = TrainConfig {
            mfs_per_input: vec![3, 2],
            epochs: 20,
            ..TrainConfig::default()
        };
        Ok(train(&data, &config)?.0)
    }

    /// Predictions agree to 4 ulp-scale relative error: serde_json without its
    /// `float_roundtrip` feature may parse a printed f64 1 ulp off.
    fn same_predictions(a: &AnfisModel, b: &AnfisModel) -> Result<usize> {
        let mut n = 0;
        for &x in &linspace(23, -12.0, 12.0) {
            for &y in &linspace(19, -12.0, 12.0) {
                let (pa, pb) = (a.predict(&[x, y])?, b.predict(&[x, y])?);
                ensure!(
                    (pa - pb).abs() <= 4.0 * f64::EPSILON * pa.abs().max(1.0),
                    "at ({x}, {y}): {pa} vs {pb}"
                );
                n += 1;
            }
        }
        Ok(n)
    }

    #[test]
    fn save_load_round_trip_gives_identical_predictions() -> Result<()> {
        let model = small_trained_model()?;
        let path = temp_path("round-trip.json");
        model.save(&path)?;
        let loaded = AnfisModel::load(&path);
        std::fs::remove_file(&path).ok();
        let loaded = loaded?;
        ensure!(loaded.input_names() == vec!["x", "y"] && loaded.output_name() == "z");
        ensure!(loaded.spec().inputs[0].range == [-5.0, 5.0]);
        ensure!(loaded.spec().rules.len() == 6);
        ensure!(same_predictions(&model, &loaded)? == 23 * 19);
        // Saving the loaded model and loading again is stable.
        let again = AnfisModel::from_json(&loaded.to_json()?)?;
        same_predictions(&loaded, &again)?;
        Ok(())
    }

    fn spec_value() -> Result<serde_json::Value> {
        Ok(serde_json::from_str(&small_trained_model()?.to_json()?)?)
    }

    /// Loads an edited model JSON and returns the error's message.
    fn load_error(edit: impl FnOnce(&mut serde_json::Value)) -> Result<(String, AnfisError)> {
        let mut v = spec_value()?;
        edit(&mut v);
        match AnfisModel::from_json(&v.to_string()) {
            Ok(_) => bail!("the edited model was accepted"),
            Err(e) => Ok((e.to_string(), e)),
        }
    }

    #[test]
    fn malformed_model_json_is_rejected_naming_the_field() -> Result<()> {
        let (msg, e) = load_error(|v| v["inputs"][1]["mfs"][0]["a"] = (-0.5).into())?;
        ensure!(matches!(e, AnfisError::InvalidModel { .. }), "{e:?}");
        ensure!(
            msg.contains("inputs[1].mfs[0].a") && msg.contains("positive"),
            "{msg}"
        );

        let (msg, _) = load_error(|v| v["inputs"][0]["mfs"][2]["b"] = 0.0.into())?;
        ensure!(msg.contains("inputs[0].mfs[2].b"), "{msg}");

        let (msg, _) = load_error(|v| v["rules"][3]["p"] = serde_json::json!([1.0]))?;
        ensure!(
            msg.contains("rules[3].p") && msg.contains("2 inputs"),
            "{msg}"
        );

        let (msg, _) = load_error(|v| v["rules"][5]["antecedent"] = serde_json::json!([3, 0]))?;
        ensure!(
            msg.contains("rules[5].antecedent[0]") && msg.contains("out of range"),
            "{msg}"
        );

        let (msg, _) = load_error(|v| v["inputs"][0]["range"] = serde_json::json!([1.0, 1.0]))?;
        ensure!(msg.contains("inputs[0].range"), "{msg}");

        let (msg, _) = load_error(|v| v["version"] = 7.into())?;
        ensure!(msg.contains("version") && msg.contains('7'), "{msg}");

        // A NaN saved by another tool comes back as null: a schema error naming the type.
        let (msg, e) = load_error(|v| v["rules"][0]["r"] = serde_json::Value::Null)?;
        ensure!(
            matches!(e, AnfisError::Json { .. }) && msg.contains("null"),
            "{msg}"
        );

        let (msg, _) = load_error(|v| v["inputs"][0]["mfs"][0]["width"] = 1.0.into())?;
        ensure!(
            msg.contains("unknown field") && msg.contains("width"),
            "{msg}"
        );

        let e = AnfisModel::from_json("{\"format\": \"ugv-anfis\", ")
            .err()
            .context("accepted")?;
        ensure!(
            matches!(e, AnfisError::Json { .. }) && e.to_string().contains("line 1"),
            "{e}"
        );
        Ok(())
    }

    #[test]
    fn hand_built_models_are_validated() -> Result<()> {
        let mf = BellMf {
            a: 0.5,
            b: 2.0,
            c: 0.0,
        };
        let good = ModelSpec {
            format: MODEL_FORMAT.into(),
            version: MODEL_VERSION,
            inputs: vec![InputSpec {
                name: "e".into(),
                range: [-1.0, 1.0],
                mfs: vec![mf, BellMf { c: 1.0, ..mf }],
            }],
            output: "steer".into(),
            rules: vec![
                RuleSpec {
                    antecedent: vec![0],
                    p: vec![2.0],
                    r: 0.0,
                },
                RuleSpec {
                    antecedent: vec![1],
                    p: vec![0.0],
                    r: 1.0,
                },
            ],
        };
        let model = AnfisModel::new(good.clone())?;
        // At u = 0 rule 0 fires fully and rule 1 with mu = 1 / (1 + 2^4) = 1/17:
        // o = (1 * 0 + (1/17) * 1) / (1 + 1/17) = 1/18.
        ensure!((model.predict(&[0.0])? - 1.0 / 18.0).abs() < 1e-15);
        let w = model.firing_strengths(&[0.0])?;
        ensure!((w[0] - 17.0 / 18.0).abs() < 1e-15 && (w.iter().sum::<f64>() - 1.0).abs() < 1e-15);

        let mut nan = good.clone();
        nan.rules[1].p[0] = f64::NAN;
        let msg = AnfisModel::new(nan)
            .err()
            .context("NaN accepted")?
            .to_string();
        ensure!(
            msg.contains("rules[1].p[0]") && msg.contains("finite"),
            "{msg}"
        );
        let mut inf = good.clone();
        inf.inputs[0].mfs[1].c = f64::INFINITY;
        let msg = AnfisModel::new(inf)
            .err()
            .context("inf accepted")?
            .to_string();
        ensure!(msg.contains("inputs[0].mfs[1].c"), "{msg}");
        let mut dup = good;
        dup.inputs.push(dup.inputs[0].clone());
        for r in &mut dup.rules {
            r.antecedent.push(0);
            r.p.push(0.0);
        }
        let msg = AnfisModel::new(dup)
            .err()
            .context("duplicate accepted")?
            .to_string();
        ensure!(
            msg.contains("inputs[1].name") && msg.contains("duplicate"),
            "{msg}"
        );
        Ok(())
    }

    #[test]
    fn predict_rejects_wrong_length_and_non_finite_inputs() -> Result<()> {
        let model = small_trained_model()?;
        ensure!(matches!(
            model.predict(&[1.0]),
            Err(AnfisError::InputLength {
                expected: 2,
                found: 1
            })
        ));
        ensure!(matches!(
            model.predict(&[1.0, 2.0, 3.0]),
            Err(AnfisError::InputLength { found: 3, .. })
        ));
        match model.predict(&[0.0, f64::NAN]) {
            Err(AnfisError::NonFiniteInput { index: 1, name, .. }) => ensure!(name == "y"),
            other => bail!("NaN input gave {other:?}"),
        }
        ensure!(matches!(
            model.predict(&[f64::NEG_INFINITY, 0.0]),
            Err(AnfisError::NonFiniteInput { index: 0, .. })
        ));
        // Far outside the training range the log-domain layers still give a finite value.
        ensure!(model.predict(&[1e6, -1e6])?.is_finite());
        Ok(())
    }

    proptest! {
        // 64 cases; no failure file (integration tests have no lib.rs beside them).
        #![proptest_config(ProptestConfig {
            cases: 64,
            failure_persistence: None,
            ..ProptestConfig::default()
        })]

        /// Model JSON encode/decode: the same parameters (to 1 ulp, see
        /// `same_predictions`) and the same predictions.
        #[test]
        fn model_json_round_trip(
            mfs in prop::collection::vec((0.01f64..3.0, 0.1f64..5.0, -2.0f64..2.0), 2..5),
            coefs in prop::collection::vec((-100.0f64..100.0, -100.0f64..100.0), 4),
            lo in -50.0f64..50.0,
            span in 0.1f64..100.0,
            x in -100.0f64..100.0,
        ) {
            let rules = (0..mfs.len())
                .map(|j| RuleSpec {
                    antecedent: vec![j],
                    p: vec![coefs[j % coefs.len()].0],
                    r: coefs[j % coefs.len()].1,
                })
                .collect();
            let spec = ModelSpec {
                format: MODEL_FORMAT.into(),
                version: MODEL_VERSION,
                inputs: vec![InputSpec {
                    name: "x".into(),
                    range: [lo, lo + span],
                    mfs: mfs.iter().map(|&(a, b, c)| BellMf { a, b, c }).collect(),
                }],
                output: "y".into(),
                rules,
            };
            let model = AnfisModel::new(spec).map_err(|e| TestCaseError::fail(e.to_string()))?;
            let json = model.to_json().map_err(|e| TestCaseError::fail(e.to_string()))?;
            let back = AnfisModel::from_json(&json).map_err(|e| TestCaseError::fail(e.to_string()))?;
            let close = |a: f64, b: f64| (a - b).abs() <= 2.0 * f64::EPSILON * a.abs();
            for (m, n) in model.spec().inputs[0].mfs.iter().zip(&back.spec().inputs[0].mfs) {
                prop_assert!(close(m.a, n.a) && close(m.b, n.b) && close(m.c, n.c));
            }
            let (p, q) = (model.predict(&[x]), back.predict(&[x]));
            let (p, q) = (p.map_err(|e| TestCaseError::fail(e.to_string()))?,
                          q.map_err(|e| TestCaseError::fail(e.to_string()))?);
            prop_assert!((p - q).abs() <= 1e-12 * p.abs().max(1.0), "{} vs {}", p, q);
        }
    }

    // ---------------------------------------------------------------- data files

    const CSV: &str = "\
# sinc samples
t, x ,\"y\",label
0.5,1.0,2.0,first

0.25, -1.5 ,3,second
";

    #[test]
    fn csv_selects_columns_by_name_in_the_given_order() -> Result<()> {
        let d = Dataset::from_csv_str(CSV, &["y", "x"], "t")?;
        ensure!(d.input_names() == names(&["y", "x"]) && d.target_name() == "t");
        let rows: Vec<&[f64]> = d.rows().collect();
        ensure!(rows == vec![&[2.0, 1.0][..], &[3.0, -1.5][..]]);
        ensure!(d.targets() == [0.5, 0.25]);
        // No inputs named: every column but the target, so the text column fails.
        let e = Dataset::from_csv_str(CSV, &[] as &[&str], "t")
            .err()
            .context("accepted")?;
        let msg = e.to_string();
        ensure!(
            msg.contains("line 3") && msg.contains("'label'") && msg.contains("'first'"),
            "{msg}"
        );
        Ok(())
    }

    #[test]
    fn malformed_csv_is_rejected_naming_line_and_column() -> Result<()> {
        let bad_number = "x,y,z\n1,2,3\n4,five,6\n";
        let e = Dataset::from_csv_str(bad_number, &["x", "y"], "z")
            .err()
            .context("accepted")?;
        match &e {
            AnfisError::Csv { line, column, .. } => ensure!(*line == 3 && column == "y", "{e}"),
            other => bail!("{other:?}"),
        }
        ensure!(e.to_string().contains("'five' is not a number"), "{e}");

        let nan = "x,y,z\n1,2,NaN\n";
        let msg = Dataset::from_csv_str(nan, &["x", "y"], "z")
            .err()
            .context("accepted")?
            .to_string();
        ensure!(
            msg.contains("line 2") && msg.contains("'z'") && msg.contains("finite"),
            "{msg}"
        );

        let short = "x,y,z\n1,2,3\n4,5\n";
        let msg = Dataset::from_csv_str(short, &["x", "y"], "z")
            .err()
            .context("accepted")?
            .to_string();
        ensure!(msg.contains("line 3") && msg.contains("2 fields"), "{msg}");

        match Dataset::from_csv_str("x,y,z\n1,2,3\n", &["x", "w"], "z") {
            Err(AnfisError::MissingColumn { name, available }) => {
                ensure!(name == "w" && available == "x, y, z")
            }
            other => bail!("{other:?}"),
        }
        let msg = Dataset::from_csv_str("x,y,z\n", &["x"], "z")
            .err()
            .context("accepted")?
            .to_string();
        ensure!(msg.contains("no data rows"), "{msg}");
        let msg = Dataset::from_csv_str("x,x,z\n1,2,3\n", &["x"], "z")
            .err()
            .context("accepted")?
            .to_string();
        ensure!(msg.contains("duplicate"), "{msg}");
        let msg = Dataset::from_csv_str("x,y\n1,2\n", &["x", "y"], "y")
            .err()
            .context("accepted")?
            .to_string();
        ensure!(msg.contains("both an input and the target"), "{msg}");
        Ok(())
    }

    #[test]
    fn json_data_in_both_layouts() -> Result<()> {
        let objects = r#"[{"x": 1, "y": 2, "z": 0.5, "note": "a"}, {"x": 3, "y": 4, "z": 0.25}]"#;
        let d = Dataset::from_json_str(objects, &["y", "x"], "z")?;
        ensure!(d.rows().collect::<Vec<_>>() == vec![&[2.0, 1.0][..], &[4.0, 3.0][..]]);
        ensure!(d.targets() == [0.5, 0.25]);

        let matrix = r#"{"inputs": [[1, 2], [3, 4]], "targets": [0.5, 0.25]}"#;
        let d = Dataset::from_json_str(matrix, &[] as &[&str], "")?;
        ensure!(d.input_names() == names(&["x1", "x2"]) && d.target_name() == "y");
        let d = Dataset::from_json_str(matrix, &["a", "b"], "z")?;
        ensure!(d.input_names() == names(&["a", "b"]) && d.target_name() == "z");

        let named = r#"{"input_names": ["p", "q"], "target_name": "r",
                    "inputs": [[1, 2], [3, 4]], "targets": [0.5, 0.25]}"#;
        let d = Dataset::from_json_str(named, &["q"], "r")?;
        ensure!(d.rows().collect::<Vec<_>>() == vec![&[2.0][..], &[4.0][..]]);

        let msg =
            Dataset::from_json_str(r#"[{"x": 1, "z": 2}, {"x": "one", "z": 3}]"#, &["x"], "z")
                .err()
                .context("accepted")?
                .to_string();
        ensure!(
            msg.contains("[1].x") && msg.contains("not a number"),
            "{msg}"
        );
        let msg = Dataset::from_json_str(r#"[{"x": 1}]"#, &["x"], "z")
            .err()
            .context("accepted")?
            .to_string();
        ensure!(msg.contains("[0].z") && msg.contains("missing"), "{msg}");
        let msg = Dataset::from_json_str(
            r#"{"inputs": [[1, 2], [3]], "targets": [1, 2]}"#,
            &[] as &[&str],
            "",
        )
        .err()
        .context("accepted")?
        .to_string();
        ensure!(
            msg.contains("inputs[1]") && msg.contains("1 values"),
            "{msg}"
        );
        let msg = Dataset::from_json_str(
            r#"{"inputs": [[1]], "targets": [1, 2]}"#,
            &[] as &[&str],
            "",
        )
        .err()
        .context("accepted")?
        .to_string();
        ensure!(msg.contains("1 input rows but 2 targets"), "{msg}");
        Ok(())
    }

    // ---------------------------------------------------------------- train command

    #[test]
    fn train_command_writes_a_model_that_reproduces_the_report() -> Result<()> {
        let data_path = temp_path("cmd-train.csv");
        let check_path = temp_path("cmd-check.csv");
        let model_path = temp_path("cmd-model.json");
        let mut train_csv = String::from("time,x,y\n");
        let mut check_csv = String::from("time,x,y\n");
        for k in 0..=40 {
            let x = -3.0 + 0.15 * f64::from(k);
            train_csv.push_str(&format!("{k},{x},{}\n", (2.0 * x).cos()));
            let xm = x + 0.075;
            check_csv.push_str(&format!("{k},{xm},{}\n", (2.0 * xm).cos()));
        }
        std::fs::write(&data_path, train_csv)?;
        std::fs::write(&check_path, check_csv)?;
        let mut args = TrainArgs::new(
            data_path.clone(),
            names(&["x"]),
            "y".into(),
            model_path.clone(),
        );
        args.mfs = vec![5];
        args.epochs = 30;
        args.checking = Some(check_path.clone());
        let result =
            train_command(&args).and_then(|report| Ok((report, AnfisModel::load(&model_path)?)));
        for p in [&data_path, &check_path, &model_path] {
            std::fs::remove_file(p).ok();
        }
        let (report, model) = result?;
        ensure!(report.training_rmse.len() == 30 && report.rules == 5);
        ensure!(model.input_names() == vec!["x"] && model.output_name() == "y");
        // The saved model is the reported best-checking epoch.
        let best = report.final_checking_rmse().context("no checking RMSE")?;
        let min = report
            .checking_rmse
            .as_ref()
            .map(|c| c.iter().copied().fold(f64::INFINITY, f64::min))
            .context("no checking RMSE")?;
        ensure!(best == min);
        let x = -1.0;
        ensure!((model.predict(&[x])? - (2.0 * x).cos()).abs() < 0.05);

        // Errors name the file.
        let mut missing = args.clone();
        missing.data = temp_path("does-not-exist.csv");
        let msg = train_command(&missing)
            .err()
            .context("accepted")?
            .to_string();
        ensure!(msg.contains("does-not-exist.csv"), "{msg}");
        let mut unknown = args;
        unknown.data = PathBuf::from("data.txt");
        ensure!(matches!(
            train_command(&unknown),
            Err(AnfisError::UnknownFormat { .. })
        ));
        ensure!("JSON".parse::<DataFormat>()? == DataFormat::Json);
        Ok(())
    }

    #[test]
    fn bad_training_configurations_are_rejected() -> Result<()> {
        let data = sinc_data(&linspace(5, -1.0, 1.0))?;
        let cases: [(&str, TrainConfig); 4] = [
            (
                "mfs_per_input",
                TrainConfig {
                    mfs_per_input: vec![2, 2, 2],
                    ..TrainConfig::default()
                },
            ),
            (
                "mfs_per_input",
                TrainConfig {
                    mfs_per_input: vec![0],
                    ..TrainConfig::default()
                },
            ),
            (
                "epochs",
                TrainConfig {
                    epochs: 0,
                    ..TrainConfig::default()
                },
            ),
            (
                "initial_step",
                TrainConfig {
                    initial_step: f64::NAN,
                    ..TrainConfig::default()
                },
            ),
        ];
        for (field, config) in cases {
            match train(&data, &config) {
                Err(AnfisError::InvalidConfig { field: f, .. }) => {
                    ensure!(f == field, "{f} vs {field}")
                }
                other => bail!("{field}: {:?}", other.map(|(_, r)| r)),
            }
        }
        // A constant input cannot be normalised.
        let flat = Dataset::new(
            names(&["x", "k"]),
            "t".into(),
            vec![vec![0.0, 1.0], vec![1.0, 1.0]],
            vec![0.0, 1.0],
        )?;
        match train(&flat, &TrainConfig::default()) {
            Err(AnfisError::DegenerateRange { name, .. }) => ensure!(name == "k"),
            other => bail!("{:?}", other.map(|(_, r)| r)),
        }
        // Selection by checking error falls back to training error without checking data.
        let config = TrainConfig {
            epochs: 5,
            selection: ModelSelection::BestChecking,
            ..TrainConfig::default()
        };
        let (_, report) = train(&data, &config)?;
        let min = report
            .training_rmse
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        ensure!(report.final_training_rmse() == min);
        Ok(())
    }

    /// `base` with its epochs, membership functions or step size each out of bounds,
    /// beside the field the refusal names.
    fn out_of_bounds(base: &TrainArgs) -> Vec<(&'static str, TrainArgs)> {
        vec![
            (
                "epochs",
                TrainArgs {
                    epochs: usize::MAX,
                    ..base.clone()
                },
            ),
            (
                "epochs",
                TrainArgs {
                    epochs: 1_000_000_000_000,
                    ..base.clone()
                },
            ),
            (
                "epochs",
                TrainArgs {
                    epochs: 0,
                    ..base.clone()
                },
            ),
            (
                "mfs",
                TrainArgs {
                    mfs: vec![100_000],
                    ..base.clone()
                },
            ),
            (
                "mfs",
                TrainArgs {
                    mfs: vec![100_000, 100_000, 100_000],
                    ..base.clone()
                },
            ),
            (
                "mfs",
                TrainArgs {
                    mfs: vec![11],
                    ..base.clone()
                },
            ),
            (
                "mfs",
                TrainArgs {
                    mfs: vec![0],
                    ..base.clone()
                },
            ),
            (
                "mfs",
                TrainArgs {
                    mfs: vec![usize::MAX, 2, 2],
                    ..base.clone()
                },
            ),
            (
                "step_size",
                TrainArgs {
                    step_size: 1e300,
                    ..base.clone()
                },
            ),
            (
                "step_size",
                TrainArgs {
                    step_size: f64::NAN,
                    ..base.clone()
                },
            ),
            (
                "step_size",
                TrainArgs {
                    step_size: -0.1,
                    ..base.clone()
                },
            ),
        ]
    }

    #[test]
    fn train_args_refuse_huge_epochs_mfs_and_rule_grids_before_reading_the_data() -> Result<()> {
        // The data file does not exist: the numbers are refused before it is read.
        let base = TrainArgs::new(
            temp_path("never-read.csv"),
            names(&["e_y", "e_theta", "phi_ref"]),
            "steer_cmd".into(),
            temp_path("never-written.json"),
        );
        let cases = out_of_bounds(&base);
        for (field, args) in cases {
            for result in [args.validate(), train_command(&args).map(|_| ())] {
                match result {
                    Err(AnfisError::InvalidConfig { field: f, reason }) => {
                        ensure!(f == field, "{f} vs {field}: {reason}");
                    }
                    other => bail!("{field}: {:?}", other),
                }
            }
        }
        // At the bounds it is accepted: 10^3 = 1000 rules, 32 MFs on one input.
        ensure!(
            TrainArgs {
                mfs: vec![10],
                epochs: 100_000,
                step_size: 1.0,
                ..base.clone()
            }
            .validate()
            .is_ok()
        );
        let one = TrainArgs {
            inputs: names(&["x"]),
            mfs: vec![32],
            ..base
        };
        ensure!(one.validate().is_ok());
        Ok(())
    }

    #[test]
    fn training_configurations_are_bounded_in_the_library_too() -> Result<()> {
        let data = sinc_data(&linspace(5, -1.0, 1.0))?;
        let cases: [(&str, TrainConfig); 4] = [
            (
                "epochs",
                TrainConfig {
                    epochs: usize::MAX,
                    ..TrainConfig::default()
                },
            ),
            (
                "mfs_per_input",
                TrainConfig {
                    mfs_per_input: vec![33],
                    ..TrainConfig::default()
                },
            ),
            (
                "mfs_per_input",
                TrainConfig {
                    mfs_per_input: vec![2, 33],
                    ..TrainConfig::default()
                },
            ),
            (
                "initial_step",
                TrainConfig {
                    initial_step: 2.0,
                    ..TrainConfig::default()
                },
            ),
        ];
        for (field, config) in cases {
            match train(&data, &config) {
                Err(AnfisError::InvalidConfig { field: f, .. }) => {
                    ensure!(f == field, "{f} vs {field}")
                }
                other => bail!("{field}: {:?}", other.map(|(_, r)| r)),
            }
        }
        Ok(())
    }
}
