//! The survey network: the hall closed on its control points, planned
//! (`predict`, `plan`, `montecarlo`) and run (`run`, `adjust`) — the
//! pre-analysis against the filter, the statistics under pure noise at
//! their nominal rates, planted blunders found, bad networks refused.

use cps::batch::{AdjustOptions, Source};
use missions::mission::Mission;
use missions::planning::Planned;
use planner::montecarlo::execute;
use rand::SeedableRng;
use serde_json::Value;
use tests::Edit;
use tests::{cps_survey, example, temp_mission};

fn json(args: &[&str]) -> Value {
    let run = cps_survey(args.iter().map(std::ffi::OsString::from));
    assert!(run.code == 0 || run.code == 1, "{}", run.stderr);
    serde_json::from_str(&run.stdout).expect("one JSON object")
}

fn sigma_xy(c: &Value) -> f64 {
    (c[0][0].as_f64().expect("cxx") + c[1][1].as_f64().expect("cyy")).sqrt()
}

/// The hall without its control points: the open traverse.
fn open_hall() -> String {
    tests::without_control(&std::fs::read_to_string(example("hall.toml")).expect("hall.toml"))
}

#[test]
fn the_pre_analysis_equals_the_filter_on_an_open_traverse() {
    // Nothing after a station tells more about it on an open traverse: the
    // batch adjustment of the planned network is the filter, station by
    // station.
    let p = json(&["predict", "--json", example("indoor-compact.toml").to_str().expect("utf-8")]);
    let cycles = p["cycles"].as_array().expect("cycles");
    let stations = p["adjusted"]["stations"].as_array().expect("adjusted stations");
    assert_eq!(stations.len(), cycles.len() + 1);
    for (c, s) in cycles.iter().zip(&stations[1..]) {
        for i in 0..4 {
            for j in 0..4 {
                let (f, a) = (c["covariance"][i][j].as_f64().expect("f"), s["covariance"][i][j].as_f64().expect("a"));
                let scale = c["covariance"][i][i].as_f64().expect("d").max(c["covariance"][j][j].as_f64().expect("d"));
                assert!((f - a).abs() <= 1e-6 * scale, "cycle {}: [{i}][{j}] {f} vs {a}", c["cycle"]);
            }
        }
    }
    let worst = stations.iter().map(|s| sigma_xy(&s["covariance"])).fold(0.0, f64::max);
    assert!((p["adjusted"]["worst_sigma_xy_m"].as_f64().expect("worst") - worst).abs() < 1e-12);
    // Every planned reading's reliability, three scalars each.
    let obs = p["adjusted"]["observations"].as_array().expect("observations");
    let kinds = ["slope_distance", "azimuth", "elevation"];
    assert!(obs.iter().all(|o| kinds.contains(&o["kind"].as_str().expect("kind"))));
    let r: f64 = obs.iter().map(|o| o["redundancy"].as_f64().expect("r")).sum();
    assert!((r - p["adjusted"]["redundancy"].as_f64().expect("redundancy")).abs() < 1e-6, "Σr = {r}");
}

#[test]
fn closing_on_control_shrinks_every_station_planned_and_achieved() {
    let hall = example("hall.toml");
    let closed = json(&["predict", "--json", hall.to_str().expect("utf-8")]);
    let open_file = temp_mission(&open_hall());
    let open = json(&["predict", "--json", open_file.path.to_str().expect("utf-8")]);
    let worst = |p: &Value| p["adjusted"]["worst_sigma_xy_m"].as_f64().expect("worst");
    let open_final = open["final"]["sigma_xy_m"].as_f64().expect("final");
    // The open traverse's worst station is its last; closing on W1, W2,
    // E1, E2 cuts the worst station's σ more than five-fold.
    assert!((worst(&open) - open_final).abs() < 1e-9, "{} vs {open_final}", worst(&open));
    assert!(worst(&closed) < open_final / 5.0, "closed {} vs open {open_final}", worst(&closed));
    // No station of the adjusted network is worse than the filter's.
    for s in closed["adjusted"]["stations"].as_array().expect("stations") {
        let filter = s["filter_sigma_xy_m"].as_f64().expect("filter σ");
        assert!(s["sigma_xy_m"].as_f64().expect("σ") <= filter * (1.0 + 1e-9), "station {}", s["index"]);
    }
    assert_eq!(closed["adjusted"]["stations"][10]["control"], serde_json::json!(["E1", "E2"]));

    // Achieved: the run's adjustment has the planned covariance and errors
    // it explains.
    let dir = tempfile::tempdir().expect("tempdir");
    let run = tests::run_mission(&hall, &dir.path().join("hall"));
    assert_eq!(run.code, 0, "{}\n{}", run.stdout, run.stderr);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("hall/report.json")).expect("report"))
            .expect("JSON");
    let adjusted = report["adjustment"]["stations"].as_array().expect("adjusted stations");
    let planned = closed["adjusted"]["stations"].as_array().expect("planned");
    assert_eq!(adjusted.len(), 22);
    // Stations next to an observation data snooping removed lose some of
    // its redundancy.
    let observations = report["adjustment"]["observations"].as_array().expect("observations");
    let near_removal = |k: i64| {
        observations.iter().any(|o| o["removed"] == true && (o["station"].as_i64().expect("station") - k).abs() <= 2)
    };
    for ((a, p), s) in adjusted.iter().zip(planned).zip(report["stations"].as_array().expect("stations")) {
        let (sa, sp) = (sigma_xy(&a["covariance"]), sigma_xy(&p["covariance"]));
        let k = a["index"].as_i64().expect("index");
        if near_removal(k) {
            assert!(sa > 0.95 * sp, "station {k}: σ {sa} vs planned {sp}");
        } else {
            assert!((sa / sp - 1.0).abs() < 0.05, "station {k}: σ {sa} vs planned {sp}");
        }
        let (tx, ty) = (s["truth"]["x_m"].as_f64().expect("x"), s["truth"]["y_m"].as_f64().expect("y"));
        let e = (a["x_m"].as_f64().expect("x") - tx).hypot(a["y_m"].as_f64().expect("y") - ty);
        assert!(e < 3.5 * sa, "station {}: adjusted error {e} m vs σ {sa} m", a["index"]);
    }
    assert_eq!(report["adjustment"]["model_accepted"], true);
}

#[test]
fn montecarlo_checks_the_adjusted_covariance_at_every_station() {
    let mc = json(&["montecarlo", "--json", "--trials", "300", example("hall.toml").to_str().expect("utf-8")]);
    let adjusted = mc["adjusted"].as_array().expect("adjusted");
    assert_eq!(adjusted.len(), 22, "every station, the resected start too");
    let (lo, hi) = (mc["adjusted_interval"][0].as_f64().expect("lo"), mc["adjusted_interval"][1].as_f64().expect("hi"));
    for s in adjusted {
        let nees = s["nees_mean"].as_f64().expect("NEES");
        assert!((lo..=hi).contains(&nees), "station {}: NEES {nees} outside [{lo}, {hi}]", s["index"]);
    }
    assert_eq!(mc["consistent"], true);
}

/// P(X ≤ k) for X ~ Binomial(n, p), summed in log space.
fn binomial_cdf(k: usize, n: usize, p: f64) -> f64 {
    let ln_choose = |n: usize, k: usize| -> f64 { (1..=k).map(|i| ((n - k + i) as f64 / i as f64).ln()).sum() };
    (0..=k.min(n)).map(|i| (ln_choose(n, i) + i as f64 * p.ln() + (n - i) as f64 * (1.0 - p).ln()).exp()).sum()
}

/// The counts a Binomial(n, p) stays within with probability 1 − 1e-4.
fn binomial_bounds(n: usize, p: f64) -> (usize, usize) {
    let lo = (0..=n).find(|&k| binomial_cdf(k, n, p) > 0.5e-4).unwrap_or(0);
    let hi = (0..=n).find(|&k| binomial_cdf(k, n, p) >= 1.0 - 0.5e-4).unwrap_or(n);
    (lo, hi)
}

#[test]
fn under_pure_noise_the_tests_raise_false_alarms_at_their_nominal_rates() {
    // Independent trials of the hall's network with the model's noise: the
    // global test rejects in α of them, and a w-test — one observation per
    // trial, in turn, so the trials stay independent — in α0 of them: each
    // count must lie where its binomial law puts it with probability
    // 1 − 1e-4. Data snooping removes no more than the w-tests flag (a false
    // alarm often shows in two correlated observations; it removes one).
    let m = Mission::load(&example("hall.toml")).expect("hall");
    let planned = Planned::new(&m).expect("plan");
    let instrument = m.total_station.clone().expect("a total station");
    let start = m.plan.start_covariance;
    let trials = 1000;
    let (alpha, alpha0) = (0.05, 0.01);
    let options = AdjustOptions { alpha, alpha0, ..AdjustOptions::default() };
    let (mut global, mut flagged, mut removed, mut sum_w2, mut n_w) = (0, 0, 0, 0.0, 0usize);
    let (mut flagged_all, mut removed_all) = (0, 0);
    for t in 0..trials {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        rng.set_stream(t as u64);
        let trial = execute(&planned.dance, &instrument, &start, &mut rng).expect("trial");
        let stations: Vec<_> = std::iter::once(trial.start).chain(trial.estimates.iter().copied()).collect();
        let net =
            planner::network::build(&planned.dance, &instrument, &start, &stations, &trial.readings).expect("network");
        let plain = cps::batch::adjust(&net.network, &AdjustOptions { snooping: false, ..options }).expect("adjust");
        global += usize::from(!plain.global_test.passed);
        // The observations snooping acts on: those others check.
        let checked: Vec<_> = plain
            .observations
            .iter()
            .filter(|o| o.w.is_some() && o.redundancy >= cps::batch::statistics::WEAKLY_CHECKED)
            .collect();
        for o in &checked {
            sum_w2 += o.w.expect("w").powi(2);
            n_w += 1;
        }
        let o = checked[t * 7919 % checked.len()];
        flagged += usize::from(o.w.expect("w").abs() > plain.w_critical);
        let snooped = cps::batch::adjust(&net.network, &options).expect("adjust");
        flagged_all += checked.iter().filter(|o| o.w.expect("w").abs() > plain.w_critical).count();
        removed_all += snooped.removed.len();
        removed += usize::from(snooped.removed.iter().any(|r| r.source == o.source && r.component == o.component));
        assert!(matches!(o.source, Source::Reading(_) | Source::PointPrior(_) | Source::StationPrior(_)));
    }
    let (glo, ghi) = binomial_bounds(trials, alpha);
    let (wlo, whi) = binomial_bounds(trials, alpha0);
    assert!((glo..=ghi).contains(&global), "global test: {global} of {trials} rejected, expected {glo}..={ghi}");
    assert!((wlo..=whi).contains(&flagged), "w-test: {flagged} of {trials} flagged, expected {wlo}..={whi}");
    assert!(removed <= flagged, "snooping removed {removed}, the w-test flagged {flagged}");
    assert!(removed_all <= flagged_all, "snooping removed {removed_all} in all, the w-tests flagged {flagged_all}");
    // And w is standard normal: E[w²] = 1.
    let mean_w2 = sum_w2 / n_w as f64;
    assert!((mean_w2 - 1.0).abs() < 0.05, "mean w² {mean_w2}");
}

#[test]
fn snooping_removes_a_2_cm_distance_blunder_wherever_its_mdb_is_below_2_cm() {
    // The planned network's readings are exact: a blunder ∇ in one reading
    // gives w = ∇/MDB·√λ0 there (above 4.1 for ∇ = 2 cm > MDB) and, by
    // Cauchy–Schwarz, no larger |w| anywhere else — snooping must remove
    // exactly that reading, every time.
    let m = Mission::load(&example("hall.toml")).expect("hall");
    let planned = Planned::new(&m).expect("plan");
    let instrument = m.total_station.clone().expect("a total station");
    let (net, clean) =
        planner::network::pre_analysis(&planned.dance, &instrument, &m.plan.start_covariance).expect("pre-analysis");
    let mut tried = 0;
    for o in clean.observations.iter().filter(|o| o.component == 0) {
        let Source::Reading(k) = o.source else { continue };
        if o.mdb.is_none_or(|mdb| mdb >= 0.02) {
            continue;
        }
        let mut blundered = net.network.clone();
        blundered.readings[k].reading.slope_m += 0.02;
        let a = cps::batch::adjust(&blundered, &AdjustOptions::default()).expect("adjust");
        assert_eq!(a.removed.len(), 1, "reading {k}: {:?}", a.removed);
        assert_eq!((a.removed[0].source, a.removed[0].component), (Source::Reading(k), 0), "reading {k}");
        assert!(a.removed[0].w.abs() > 0.02 / o.mdb.expect("mdb") * 4.0, "reading {k}: w {}", a.removed[0].w);
        tried += 1;
    }
    // Most distances are checked that well (the hall's MDBs are millimetres).
    let distances = net.network.readings.len();
    assert!(tried * 10 > distances * 9, "{tried} of {distances} distances have an MDB below 2 cm");
}

#[test]
fn a_planted_blunder_in_a_simulated_run_is_found_and_removed() {
    let dir = tempfile::tempdir().expect("tempdir");
    let hall = example("hall.toml");
    let clean = tests::run_mission(&hall, &dir.path().join("clean"));
    assert_eq!(clean.code, 0, "{}", clean.stderr);
    let report = |d: &str| -> Value {
        serde_json::from_str(&std::fs::read_to_string(dir.path().join(d).join("report.json")).expect("report"))
            .expect("JSON")
    };
    let clean_report = report("clean");
    let observations = clean_report["adjustment"]["observations"].as_array().expect("observations").clone();
    // A fix distance well checked (MDB under 1 cm: a 2 cm blunder is found
    // with certainty), not removed in the clean run.
    let chosen = observations
        .iter()
        .filter(|o| o["kind"] == "slope_distance" && o["removed"] == false)
        .filter(|o| o["mdb"].as_f64().is_some_and(|mdb| mdb < 0.01))
        .nth(20)
        .expect("a well-checked distance");
    let index = chosen["index"].as_u64().expect("index");
    // The N-th distance measured is reading N − 1 of the network (no
    // retries on the clean simulator).
    let n = index / 3 + 1;
    let mut args: Vec<std::ffi::OsString> = vec!["run".into(), hall.clone().into_os_string(), "--out".into()];
    args.extend([dir.path().join("blunder").into_os_string(), "--quiet".into(), "--sim-fault".into()]);
    args.push(format!("total-station:blunder={n}:0.02").into());
    let run = cps_survey(args);
    assert!(run.code == 0 || run.code == 1, "{}", run.stderr);
    let blundered = report("blunder");
    let a = &blundered["adjustment"];
    let removed: Vec<u64> = a["removed"].as_array().expect("removed").iter().map(|r| r.as_u64().expect("i")).collect();
    assert!(removed.contains(&index), "observation {index} ({chosen}) not removed: {removed:?}");
    let o = &a["observations"][index as usize];
    assert!(run.stdout.contains(&format!("observation {index}:")), "the summary names it: {}", run.stdout);
    assert_eq!(o["removed"], true);
    assert!(o["w"].as_f64().expect("w").abs() > 5.0, "{o}");
    // The blunder is 2 cm on that distance; every reading before it is
    // unchanged (same seed). Later ones draw the same noise, but the robots
    // steer by estimates the blunder moved: they differ by that much only.
    let value = |r: &Value, i: usize| r["adjustment"]["observations"][i]["value"].as_f64().expect("value");
    let index = index as usize;
    for i in 0..observations.len() {
        let d = value(&blundered, i) - value(&clean_report, i);
        match i.cmp(&index) {
            std::cmp::Ordering::Less => assert!(d.abs() < 1e-9, "observation {i}: changed by {d}"),
            std::cmp::Ordering::Equal => assert!((d - 0.02).abs() < 1e-9, "the blunder: {d}"),
            std::cmp::Ordering::Greater if i % 3 == 0 => assert!(d.abs() < 0.05, "observation {i}: changed by {d}"),
            std::cmp::Ordering::Greater => {}
        }
    }
}

#[test]
fn plan_lists_the_sightings_and_optimizes_for_every_station() {
    let text = std::fs::read_to_string(example("hall.toml")).expect("hall.toml");
    let text = text.edit("max_final_sigma_xy_m = 0.05", "max_final_sigma_xy_m = 0.05\nmax_station_sigma_xy_m = 0.004");
    let mission = temp_mission(&text);
    let path = mission.path.to_str().expect("utf-8");
    let p = json(&["plan", "--json", path]);
    // Which station sees which control point, at what distance.
    let control = p["control"].as_array().expect("control");
    let names: Vec<&str> = control.iter().map(|c| c["name"].as_str().expect("name")).collect();
    assert_eq!(names, ["W1", "W2", "E1", "E2"]);
    let from = |c: &Value| -> Vec<u64> {
        c["seen_from"].as_array().expect("seen_from").iter().map(|s| s["station"].as_u64().expect("k")).collect()
    };
    assert_eq!(from(&control[0]), [0, 21]);
    assert_eq!(from(&control[2]), [10]);
    assert_eq!((control[0]["fixed"].clone(), control[2]["fixed"].clone()), (Value::Bool(true), Value::Bool(false)));
    assert_eq!(p["control_at"], "[0, 10, 21]");
    // --optimize meets every station's tolerance, and its file predicts it.
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("optimized.toml");
    let o = json(&["plan", "--json", path, "--optimize", "--out", out.to_str().expect("utf-8")]);
    let worst = o["optimized"]["worst_station_sigma_xy_m"].as_f64().expect("worst");
    assert!(worst <= 0.004, "{}", o["optimized"]);
    assert_eq!(o["accepted"], true);
    let again = json(&["predict", "--json", out.to_str().expect("utf-8")]);
    assert!((again["adjusted"]["worst_sigma_xy_m"].as_f64().expect("worst") - worst).abs() < 1e-9);
    assert_eq!(again["adjusted"]["accepted"], true);
    let written = std::fs::read_to_string(&out).expect("optimized file");
    let at = o["optimized"]["control_at"].as_str().expect("control_at");
    assert!(written.contains(&format!("control_at = {at}")) || at == "[0, 10, 21]", "{written}");
}

#[test]
fn adjust_reads_a_run_and_refuses_a_broken_journal() {
    let dir = tempfile::tempdir().expect("tempdir");
    let run_dir = dir.path().join("hall");
    let run = tests::run_mission(&example("hall.toml"), &run_dir);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let report: Value =
        serde_json::from_str(&std::fs::read_to_string(run_dir.join("report.json")).expect("report")).expect("JSON");
    let dir_arg = run_dir.to_str().expect("utf-8");

    // The same object as report.json's, with the keys the issue lists.
    let a = json(&["adjust", dir_arg, "--json"]);
    assert_eq!(a, report["adjustment"]);
    for key in ["sigma0_squared", "redundancy", "iterations", "converged", "global_test", "stations", "points"] {
        assert!(!a[key].is_null(), "{key}");
    }
    for key in ["statistic", "dof", "alpha", "lower", "upper", "passed"] {
        assert!(!a["global_test"][key].is_null(), "global_test.{key}");
    }
    let s = &a["stations"][3];
    assert_eq!(s["covariance"].as_array().map(Vec::len), Some(4));
    let o = &a["observations"][0];
    for key in ["index", "station", "target", "kind", "value", "sigma", "residual", "redundancy", "w", "mdb", "removed"]
    {
        assert!(o.get(key).is_some(), "observations[].{key}");
    }
    let points: Vec<&str> =
        a["points"].as_array().expect("points").iter().map(|p| p["id"].as_str().expect("id")).collect();
    assert!(
        a["observations"].as_array().expect("obs").iter().all(|o| points.contains(&o["target"].as_str().expect("t")))
    );
    // Σ r = redundancy (the readings' and the prior coordinates').
    let r: f64 = a["observations"]
        .as_array()
        .expect("obs")
        .iter()
        .filter(|o| o["removed"] == false)
        .chain(a["coordinate_observations"].as_array().expect("coordinates"))
        .map(|o| o["redundancy"].as_f64().expect("r"))
        .sum();
    assert!((r - a["redundancy"].as_f64().expect("redundancy")).abs() < 1e-6, "Σr {r} vs {}", a["redundancy"]);
    // The options reach the tests.
    let strict = json(&["adjust", dir_arg, "--json", "--alpha0", "0.05", "--no-snooping"]);
    assert_eq!(strict["removed"].as_array().map(Vec::len), Some(0));
    assert!((strict["testing"]["w_critical"].as_f64().expect("w") - 1.959_963_984_540_054).abs() < 1e-9);
    let listing = std::fs::read_to_string(run_dir.join("adjustment.txt")).expect("adjustment.txt");
    for section in ["Control points", "Adjusted stations", "global test", "Observations"] {
        assert!(listing.to_lowercase().contains(&section.to_lowercase()), "adjustment.txt lacks {section}");
    }

    // A journal whose reading is not a number (a NaN is written as null):
    // exit 2 naming the line; the journal and the listing stay as they were.
    let journal = std::fs::read_to_string(run_dir.join("journal.jsonl")).expect("journal");
    let line = journal.lines().position(|l| l.contains("\"event\":\"measure\"")).expect("a measure") + 1;
    let broken = journal
        .lines()
        .enumerate()
        .map(|(i, l)| {
            if i + 1 == line {
                let (head, tail) = l.split_once("\"slope_raw_m\":").expect("slope");
                let rest = &tail[tail.find(',').expect("next field")..];
                format!("{head}\"slope_raw_m\":null{rest}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + "\n";
    std::fs::write(run_dir.join("journal.jsonl"), &broken).expect("write");
    let before = std::fs::read_to_string(run_dir.join("adjustment.txt")).expect("listing");
    let failed = cps_survey(["adjust", dir_arg]);
    assert_eq!(failed.code, 2, "{}", failed.stderr);
    assert!(failed.stderr.contains(&format!("journal.jsonl:{line}")), "{}", failed.stderr);
    assert_eq!(std::fs::read_to_string(run_dir.join("journal.jsonl")).expect("journal"), broken);
    assert_eq!(std::fs::read_to_string(run_dir.join("adjustment.txt")).expect("listing"), before);
    // Not a run directory at all.
    let missing = cps_survey(["adjust", dir.path().join("nowhere").to_str().expect("utf-8")]);
    assert_eq!(missing.code, 2);
    assert!(missing.stderr.contains("nowhere"), "{}", missing.stderr);
}

#[test]
fn a_global_test_that_fails_exits_1() {
    // A 5 cm blunder on a distance, kept (no snooping): vᵀPv far beyond
    // the χ² bound.
    let dir = tempfile::tempdir().expect("tempdir");
    let mut args: Vec<std::ffi::OsString> = vec!["run".into(), example("hall.toml").into_os_string(), "--out".into()];
    args.extend([dir.path().join("r").into_os_string(), "--quiet".into(), "--sim-fault".into()]);
    args.push("total-station:blunder=30:0.05".into());
    let run = cps_survey(args);
    assert!(run.code <= 1, "{}", run.stderr);
    let adjusted = cps_survey(["adjust", dir.path().join("r").to_str().expect("utf-8"), "--no-snooping"]);
    assert_eq!(adjusted.code, 1, "{}\n{}", adjusted.stdout, adjusted.stderr);
    assert!(adjusted.stdout.contains("FAIL"), "{}", adjusted.stdout);
}

#[test]
fn an_angle_blunder_strikes_one_horizontal_direction() {
    // `blunder-angle=N:ARCSEC` turns the N-th horizontal direction (Hz,
    // clockwise) by ARCSEC: the adjustment's azimuth (counter-clockwise)
    // of that reading moves by −ARCSEC, and nothing before it moves.
    let dir = tempfile::tempdir().expect("tempdir");
    let hall = example("hall.toml");
    let run = |name: &str, fault: Option<&str>| -> Value {
        let mut args: Vec<std::ffi::OsString> = vec!["run".into(), hall.clone().into_os_string(), "--out".into()];
        args.extend([dir.path().join(name).into_os_string(), "--quiet".into()]);
        if let Some(f) = fault {
            args.extend(["--sim-fault".into(), f.into()]);
        }
        let r = cps_survey(args);
        assert!(r.code <= 1, "{}", r.stderr);
        serde_json::from_str(&std::fs::read_to_string(dir.path().join(name).join("report.json")).expect("report"))
            .expect("JSON")
    };
    let clean = run("clean", None);
    let turned = run("turned", Some("total-station:blunder-angle=7:30"));
    let azimuth = |r: &Value, i: usize| r["adjustment"]["observations"][3 * i + 1]["value"].as_f64().expect("value");
    for i in 0..6 {
        let d = azimuth(&turned, i) - azimuth(&clean, i);
        assert!(d.abs() < 1e-12, "reading {i}: {d}");
    }
    let d = cps::wrap_angle(azimuth(&turned, 6) - azimuth(&clean, 6));
    assert!((d + 30.0 * cps::RAD_PER_ARCSEC).abs() < 1e-9, "the 7th reading turned by {} ″", d / cps::RAD_PER_ARCSEC);
    let slope = |r: &Value| r["adjustment"]["observations"][18]["value"].as_f64().expect("value");
    assert!((slope(&turned) - slope(&clean)).abs() < 1e-12, "its distance is untouched");
    // Bad fault specifications name what is expected.
    let bad = cps_survey(["run", hall.to_str().expect("utf-8"), "--sim-fault", "tilt:blunder=3:0.02"]);
    assert_eq!(bad.code, 2);
    assert!(bad.stderr.contains("blunders are the total station's"), "{}", bad.stderr);
}

#[test]
fn a_plan_the_adjustment_cannot_take_keeps_its_prediction() {
    // 500 km of the paper's traverse: its far end is known to kilometres,
    // beyond what double precision tells from undetermined. The filter's
    // prediction stands, the pre-analysis says why it is missing, and a
    // tolerance on every station cannot pass unchecked.
    let text = std::fs::read_to_string(example("paper-1km.toml")).expect("paper-1km.toml");
    let text = text
        .edit("[1000.0, 0.0, 0.0]]", "[500000.0, 0.0, 0.0]]")
        .edit("max_final_sigma_xy_m = 0.25", "max_final_sigma_xy_m = 1000000.0\nmax_station_sigma_xy_m = 1000000.0");
    let mission = temp_mission(&text);
    let run = cps_survey(["predict", "--json", mission.path.to_str().expect("utf-8")]);
    assert_eq!(run.code, 1, "{}", run.stderr);
    let p: Value = serde_json::from_str(&run.stdout).expect("JSON");
    assert_eq!(p["cycles"].as_array().map(Vec::len), Some(50_000));
    assert!(p["adjusted"].is_null());
    assert!(p["adjusted_error"].as_str().is_some_and(|e| e.contains("cannot be adjusted")), "{}", p["adjusted_error"]);
    assert_eq!(p["final"]["accepted"], false);
}
