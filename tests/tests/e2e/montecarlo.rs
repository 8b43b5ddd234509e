//! `cps-survey montecarlo`: the spread of seeded simulated executions agrees
//! with the prediction `predict` gives for the same mission.

use serde_json::Value;
use tests::{cps_survey, example};

#[test]
fn hall_positioning_agrees_with_its_prediction() {
    let hall = example("hall.toml").into_os_string();
    let mc = cps_survey(["montecarlo".into(), hall.clone(), "--trials".into(), "400".into(), "--json".into()]);
    assert_eq!(mc.code, 0, "{}\n{}", mc.stdout, mc.stderr);
    let mc: Value = serde_json::from_str(&mc.stdout).expect("one JSON object");
    let predict = cps_survey(["predict".into(), hall, "--json".into()]);
    let predict: Value = serde_json::from_str(&predict.stdout).expect("predict JSON");

    assert_eq!(mc["trials"], 400);
    let stations = mc["stations"].as_array().expect("stations");
    assert_eq!(stations.len(), 21, "one per dance cycle");
    // The predicted figure is predict's final σx² + σy².
    let predicted = mc["predicted_sigma_xy2_m2"].as_f64().expect("predicted");
    let from_predict = predict["cycles"].as_array().and_then(|c| c.last()).expect("cycles")["sigma_xy2_m2"]
        .as_f64()
        .expect("sigma_xy2_m2");
    assert!((predicted / from_predict - 1.0).abs() < 1e-12, "{predicted} vs {from_predict}");
    // 400 trials estimate σx² + σy² to about ±7 % (1σ): allow ±25 %.
    let ratio = mc["ratio"].as_f64().expect("ratio");
    assert!((0.75..1.25).contains(&ratio), "empirical / predicted = {ratio}");
    let empirical = mc["empirical_sigma_xy2_m2"].as_f64().expect("empirical");
    assert!((empirical / predicted - ratio).abs() < 1e-12);
    // The mean NEES lies in its interval, which brackets the dimension 4.
    let (lo, hi) = (mc["nees_interval"][0].as_f64().expect("lo"), mc["nees_interval"][1].as_f64().expect("hi"));
    assert!(lo < 4.0 && 4.0 < hi);
    let nees = mc["nees_mean"].as_f64().expect("nees");
    assert!((lo..=hi).contains(&nees), "NEES {nees} outside [{lo}, {hi}]");
    assert_eq!(mc["consistent"], true);
}

#[test]
fn too_few_trials_is_an_error() {
    let run = cps_survey(["montecarlo".into(), example("hall.toml").into_os_string(), "--trials".into(), "1".into()]);
    assert_eq!(run.code, 2);
    assert!(run.stderr.contains("--trials 1"), "{}", run.stderr);
}
