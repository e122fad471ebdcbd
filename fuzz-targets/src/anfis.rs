//! ANFIS files: the model JSON the follower loads (`AnfisModel::load` reads the file
//! and calls `AnfisModel::from_json`) and the training CSV `anfis train` reads
//! (`Dataset::load` calls `Dataset::from_csv_str`).

use ugv_controller::anfis::{AnfisModel, Dataset, TrainConfig, train};

/// The inputs and target `scripts/lab/compare-followers.sh` trains on (the columns of the
/// controller's training.csv).
const INPUTS: [&str; 3] = ["e_y", "e_theta", "phi_ref"];
const TARGET: &str = "steer_cmd";

/// Data sets up to this size are also trained on (two epochs, two MFs per input, as
/// the comparison study does with more epochs); larger ones only load. Training is
/// the product's next step, but its work grows with rows x MFs^inputs.
const TRAIN_MAX_ROWS: usize = 64;
const TRAIN_MAX_INPUTS: usize = 3;

/// `anfis_model`: the bytes as a model file (UTF-8 text, `AnfisModel::from_json`).
///
/// Invariants of a model that loads: it saves (`to_json`) and loads back equal; its
/// output at a few inputs (zeros, the ends and middles of the normalisation ranges, far
/// outside them) is finite or an error, never NaN; the firing strengths there are in
/// [0, 1] and sum to 1.
pub fn anfis_model(data: &[u8]) {
    let Some(text) = crate::text(data) else {
        return;
    };
    let Ok(model) = AnfisModel::from_json(text) else {
        return;
    };
    let json = match model.to_json() {
        Ok(j) => j,
        Err(e) => panic!("a loaded model does not save: {e}"),
    };
    match AnfisModel::from_json(&json) {
        Ok(back) => assert_eq!(back, model, "the model does not round trip"),
        Err(e) => panic!("a saved model does not load: {e}\n{json}"),
    }
    let ranges: Vec<[f64; 2]> = model.spec().inputs.iter().map(|i| i.range).collect();
    let points: [Box<dyn Fn([f64; 2]) -> f64>; 5] = [
        Box::new(|_| 0.0),
        Box::new(|r| r[0]),
        Box::new(|r| r[1]),
        Box::new(|r| r[0] / 2.0 + r[1] / 2.0),
        Box::new(|r| r[1] + 1e6 * (r[1] - r[0])),
    ];
    for point in &points {
        let x: Vec<f64> = ranges.iter().map(|r| point(*r)).collect();
        if x.iter().any(|v| !v.is_finite()) {
            continue;
        }
        if let Ok(y) = model.predict(&x) {
            assert!(y.is_finite(), "predict({x:?}) = {y}");
        }
        if let Ok(w) = model.firing_strengths(&x) {
            assert!(
                w.iter().all(|v| (0.0..=1.0).contains(v)),
                "firing strengths at {x:?}: {w:?}"
            );
            let sum: f64 = w.iter().sum();
            assert!(
                (sum - 1.0).abs() < 1e-9,
                "firing strengths sum to {sum} at {x:?}"
            );
        }
    }
}

/// `anfis_csv`: the bytes as a training CSV (UTF-8 text, `Dataset::from_csv_str`) with
/// the columns the comparison study names (`--inputs e_y,e_theta,phi_ref --target
/// steer_cmd`) and with every column but the target (no `--inputs`).
///
/// Invariants of a data set that loads: it has rows, every value is finite, the rows
/// have one value per input; a small one trains (two epochs) to a valid model or an
/// error, and the trained model's output on the training rows is finite.
pub fn anfis_csv(data: &[u8]) {
    let Some(text) = crate::text(data) else {
        return;
    };
    let no_inputs: [&str; 0] = [];
    for set in [
        Dataset::from_csv_str(text, &INPUTS, TARGET),
        Dataset::from_csv_str(text, &no_inputs, TARGET),
    ] {
        let Ok(set) = set else { continue };
        check_dataset(&set);
    }
}

fn check_dataset(set: &Dataset) {
    assert!(!set.is_empty());
    assert_eq!(set.targets().len(), set.len());
    let n = set.n_inputs();
    assert_eq!(set.input_names().len(), n);
    let mut rows = 0;
    for row in set.rows() {
        assert_eq!(row.len(), n);
        assert!(row.iter().all(|v| v.is_finite()), "{row:?}");
        rows += 1;
    }
    if n > 0 {
        assert_eq!(rows, set.len());
    }
    assert!(set.targets().iter().all(|v| v.is_finite()));
    if n == 0 || n > TRAIN_MAX_INPUTS || set.len() > TRAIN_MAX_ROWS {
        return;
    }
    let config = TrainConfig {
        mfs_per_input: vec![2],
        epochs: 2,
        ..TrainConfig::default()
    };
    let Ok((model, _report)) = train(set, &config) else {
        return;
    };
    if let Err(e) = AnfisModel::new(model.spec().clone()) {
        panic!("training returned an invalid model: {e}");
    }
    for row in set.rows() {
        if let Ok(y) = model.predict(row) {
            assert!(y.is_finite(), "the trained model gives {y} at {row:?}");
        }
    }
}
