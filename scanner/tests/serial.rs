//! Our serial drivers against our emulators on pseudo-terminals: normal
//! measurements agree with the simulated truth, and every injected fault
//! is either recovered from (retry, resync) or ends in a typed error within
//! the driver's deadline.

use std::time::{Duration, Instant};

use cps::{Instrument, ParentPose, RAD_PER_ARCSEC, observe};
use nalgebra::Point3;
use scanner::emulate::geocom::GeoComEmulator;
use scanner::emulate::nmea::NmeaTiltEmulator;
use scanner::emulate::{Emulator, Faults};
use scanner::protocol::geocom::ReturnCode;
use scanner::serial::Port;
use scanner::serial::geocom::{GeoCom, GeoComConfig};
use scanner::serial::nmea::NmeaTilt;
use scanner::sim::{SimTilt, SimWorld, Truth};
use scanner::{ScannerError, Target, Tilt, TiltSensor, TotalStation};

fn instrument() -> Instrument {
    Instrument {
        sigma_distance_m: 0.003,
        sigma_hz_rad: 5.0 * RAD_PER_ARCSEC,
        sigma_v_rad: 5.0 * RAD_PER_ARCSEC,
        min_range_m: 1.0,
        max_range_m: 100.0,
        ..Instrument::default()
    }
}

fn world() -> SimWorld {
    // The hall example's first cycle: clear sight lines.
    let parent = ParentPose::new(2.0, 4.5, 1.5, 0.1);
    let children = vec![Point3::new(6.0, 7.0, 1.0), Point3::new(6.0, 3.0, 1.0)];
    SimWorld::new(cps::geom::builtin("hall").expect("hall"), parent, children)
}

fn target(world: &SimWorld, child: usize) -> Target {
    let t = world.truth();
    Target { child, predicted: observe(&t.parent, &t.children[child]).expect("reading") }
}

fn station(world: &SimWorld, config: GeoComConfig) -> (Emulator, GeoCom) {
    let emulator = Emulator::spawn(GeoComEmulator::new(world.clone(), instrument(), 7, 9600)).expect("emulator");
    let port = Port::open("total station", emulator.path(), 9600).expect("port");
    let mut driver = GeoCom::new(port, config);
    driver.connect().expect("the link answers");
    (emulator, driver)
}

fn quick() -> GeoComConfig {
    GeoComConfig { reply_timeout: Duration::from_millis(300), ..GeoComConfig::default() }
}

/// Measures both children and checks the readings against the truth (5σ).
fn measures_both(world: &SimWorld, driver: &mut GeoCom) {
    let inst = instrument();
    for j in 0..2 {
        let t = target(world, j);
        let m = driver.measure(&t).expect("measured");
        let r = m.to_reading(&inst);
        let exact = t.predicted;
        assert!((r.slope_m - exact.slope_m).abs() < 5.0 * 0.004, "{r:?} vs {exact:?}");
        assert!(cps::wrap_angle(r.azimuth_rad - exact.azimuth_rad).abs() < 5.0 * 6.0 * RAD_PER_ARCSEC);
        assert!((r.elevation_rad - exact.elevation_rad).abs() < 5.0 * 6.0 * RAD_PER_ARCSEC);
    }
}

#[test]
fn geocom_measures_the_children() {
    let w = world();
    let (emulator, mut driver) = station(&w, quick());
    measures_both(&w, &mut driver);
    assert_eq!(driver.discarded, 0);
    // Closed and reopened (the emulator keeps the pty), without the CRC field.
    drop(driver);
    let port = Port::open("total station", emulator.path(), 9600);
    let mut plain = GeoCom::new(port.expect("reopened"), GeoComConfig { checksum: false, ..quick() });
    plain.connect().expect("link");
    measures_both(&w, &mut plain);
    emulator.stop().expect("clean stop");
}

#[test]
fn geocom_recovers_from_corrupt_dropped_duplicated_and_rejected_replies() {
    let w = world();
    for faults in [
        Faults { corrupt_every: Some(3), ..Faults::default() },
        Faults { drop_every: Some(97), ..Faults::default() },
        Faults { duplicate_every: Some(89), ..Faults::default() },
        Faults { nak_every: Some(4), ..Faults::default() },
    ] {
        let (emulator, mut driver) = station(&w, quick());
        emulator.set_faults(faults.clone());
        measures_both(&w, &mut driver);
        measures_both(&w, &mut driver);
        assert!(emulator.messages() > 8, "{faults:?}");
    }
}

#[test]
fn geocom_fails_typed_and_in_time() {
    let w = world();
    let config = GeoComConfig { reply_timeout: Duration::from_millis(200), attempts: 2, ..GeoComConfig::default() };
    // A device that stops answering: a timeout after 2 × 200 ms.
    let (emulator, mut driver) = station(&w, config);
    emulator.set_faults(Faults { stop_after: Some(emulator.messages()), ..Faults::default() });
    let started = Instant::now();
    let e = driver.measure(&target(&w, 0)).expect_err("no answer");
    let took = started.elapsed();
    assert!(matches!(e, ScannerError::Timeout { attempts: 2, .. }), "{e}");
    assert!(took >= Duration::from_millis(400) && took < Duration::from_millis(1500), "{took:?}");
    assert!(e.to_string().contains("AUT_MakePositioning (9027)"), "{e}");

    // Aimed where no prism is: the instrument's own error, typed.
    let (_emulator, mut driver) = station(&w, config);
    let mut away = target(&w, 0);
    away.predicted.azimuth_rad += 0.5;
    match driver.measure(&away) {
        Err(ScannerError::Instrument { code: ReturnCode::NoTarget, request, .. }) => {
            assert!(request.contains("AUT_FineAdjust"), "{request}")
        }
        other => panic!("expected no target, got {other:?}"),
    }

    // Replies too slow for the deadline: the late reply to the first
    // attempt is recognised by its transaction id and skipped.
    let (emulator, mut driver) = station(&w, config);
    emulator.set_faults(Faults { delay: Duration::from_millis(300), ..Faults::default() });
    let e = driver.measure(&target(&w, 0)).expect_err("too slow");
    assert!(matches!(e, ScannerError::Timeout { .. }), "{e}");
    assert!(driver.discarded >= 1, "the late reply was skipped");

    // The instrument set to another baud rate: never understood.
    let (emulator, mut driver) = station(&w, config);
    emulator.set_faults(Faults { baud: Some(19200), ..Faults::default() });
    assert!(matches!(driver.measure(&target(&w, 1)), Err(ScannerError::Timeout { .. })));
    // Back at the right rate, the same driver goes on.
    emulator.set_faults(Faults::default());
    measures_both(&w, &mut driver);
}

fn tilted_world(roll_deg: f64, pitch_deg: f64) -> SimWorld {
    let w = world();
    let t = w.truth();
    w.set_truth(Truth { tilt: Tilt { roll_rad: roll_deg.to_radians(), pitch_rad: pitch_deg.to_radians() }, ..t });
    w
}

fn tilt_sensor(w: &SimWorld) -> (Emulator, NmeaTilt) {
    let sim = SimTilt::new(w.clone(), 1e-5, 3);
    let emulator = Emulator::spawn(NmeaTiltEmulator::new(sim, 50.0, 9600)).expect("emulator");
    let port = Port::open("tilt sensor", emulator.path(), 9600).expect("port");
    // A generous staleness window (10 periods): the test machine may be busy.
    (emulator, NmeaTilt::new(port, Duration::from_millis(20), 10.0))
}

#[test]
fn tilt_reads_the_truth_skips_bad_lines_and_reports_stale_data() {
    let w = tilted_world(1.5, -0.75);
    let (emulator, mut sensor) = tilt_sensor(&w);
    for _ in 0..3 {
        let t = sensor.read().expect("a reading");
        // 3 decimals of a degree on the wire: ±0.0005° plus the noise.
        assert!((t.roll_rad - 1.5f64.to_radians()).abs() < 2e-5, "{t:?}");
        assert!((t.pitch_rad + 0.75f64.to_radians()).abs() < 2e-5, "{t:?}");
    }
    emulator.set_faults(Faults { corrupt_every: Some(3), ..Faults::default() });
    for _ in 0..5 {
        sensor.read().expect("a valid line among corrupt ones");
    }
    assert!(sensor.rejected >= 1, "corrupt lines were skipped");
    emulator.set_faults(Faults { stop_after: Some(0), ..Faults::default() });
    let started = Instant::now();
    let e = sensor.read().expect_err("stale");
    assert!(matches!(e, ScannerError::Stale { .. }), "{e}");
    // The deadline is 11 periods (220 ms); allow for a busy machine.
    let took = started.elapsed();
    assert!(took >= Duration::from_millis(220) && took < Duration::from_millis(2000), "{took:?}");
}
