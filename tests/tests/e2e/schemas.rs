//! The versioned JSON contract: `docs/schemas/` is what `cps-survey
//! schemas` generates from the types that write the documents, and every
//! document opens with its schema's version and the tool's. (CI validates
//! real outputs of every command against these schemas with Python's
//! `jsonschema`: `.ci/check_schemas.py`.)

use serde_json::Value;
use tests::{cps_survey, example, workspace};

const DOCUMENTS: [&str; 9] =
    ["report", "fusion", "adjust", "predict", "plan", "montecarlo", "register", "match", "emulate"];

#[test]
fn docs_schemas_are_the_generated_ones() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let run = cps_survey(["schemas".into(), "--out".into(), dir.path().as_os_str().to_owned()]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let docs = workspace().join("docs/schemas");
    let mut committed: Vec<String> = std::fs::read_dir(&docs)
        .expect("docs/schemas")
        .map(|e| e.expect("an entry").file_name().to_string_lossy().into_owned())
        .collect();
    committed.sort();
    let mut expected: Vec<String> = DOCUMENTS.iter().map(|d| format!("{d}.schema.json")).collect();
    expected.sort();
    assert_eq!(committed, expected, "docs/schemas/ holds one schema per document");
    for file in &expected {
        let generated = std::fs::read_to_string(dir.path().join(file)).expect("generated");
        let written = std::fs::read_to_string(docs.join(file)).expect("committed");
        assert!(
            generated == written,
            "docs/schemas/{file} is not what the types generate: \
             run `cargo run --release -p missions -- schemas --out docs/schemas` and commit"
        );
        let schema: Value = serde_json::from_str(&generated).expect("a schema is JSON");
        assert_eq!(schema["$schema"], "https://json-schema.org/draft/2020-12/schema");
        for key in ["schema_version", "tool_version"] {
            assert!(schema["properties"][key].is_object(), "{file} describes {key}");
            assert!(schema["required"].as_array().is_some_and(|r| r.iter().any(|k| k == key)), "{file} requires {key}");
        }
    }
}

#[test]
fn one_schema_prints_and_an_unknown_one_is_named() {
    let run = cps_survey(["schemas", "fusion"]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let schema: Value = serde_json::from_str(&run.stdout).expect("JSON");
    assert_eq!(schema["title"], "cps-survey fusion document, schema version 1");
    let covariance = &schema["$defs"]["FusedScanReport"]["properties"]["covariance"]["description"];
    assert!(covariance.as_str().is_some_and(|d| d.contains("(ω_x, ω_y, ω_z, x, y, z)")), "{covariance}");
    let run = cps_survey(["schemas", "reprot"]);
    assert_eq!(run.code, 2);
    assert!(
        run.stderr.contains("no document named \"reprot\"") && run.stderr.contains("report, fusion"),
        "{}",
        run.stderr
    );
}

/// The header, and each deprecated key equal to the key that replaces it.
#[test]
fn predict_and_plan_carry_the_header_and_one_meaning_per_key() {
    let hall = example("hall.toml").into_os_string();
    let run = cps_survey(["predict".into(), hall.clone(), "--json".into()]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let v: Value = serde_json::from_str(&run.stdout).expect("JSON");
    assert_eq!(v["schema_version"], 1);
    assert_eq!(v["tool_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(v["final"]["drift_percent"], v["final"]["sigma_drift_percent"]);
    let f = &v["final"];
    let sigma = f["sigma_xy_m"].as_f64().expect("σ");
    let distance = f["distance_m"].as_f64().expect("distance");
    let drift = f["sigma_drift_percent"].as_f64().expect("drift");
    assert!((drift - 100.0 * sigma / distance).abs() < 1e-9 * drift, "{drift} vs {sigma} / {distance}");
    for c in v["cycles"].as_array().expect("cycles") {
        assert_eq!(c["drift_percent"], c["sigma_drift_percent"]);
    }
    for s in v["steps"].as_array().expect("steps") {
        let p = &s["position"];
        assert_eq!(s["position_m"], serde_json::json!([p["x_m"], p["y_m"], p["z_m"]]));
    }

    let run = cps_survey(["plan".into(), hall, "--json".into()]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let v: Value = serde_json::from_str(&run.stdout).expect("JSON");
    assert_eq!(v["schema_version"], 1);
    assert_eq!(v["tool_version"], env!("CARGO_PKG_VERSION"));
    assert_eq!(v["station_count"], 22, "the hall has 22 stations");
    for (old, new) in [("stations", "station_count"), ("cycles", "cycle_count"), ("steps", "step_count")] {
        assert!(v[new].as_u64().is_some_and(|n| n > 0), "{new}");
        assert_eq!(v[old], v[new]);
    }
}
