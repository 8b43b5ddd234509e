//! Our serial drivers against our emulators on pseudo-terminals: normal
//! measurements agree with the simulated truth, and every injected fault
//! is either recovered from (retry, resync) or ends in a typed error within
//! the driver's deadline.

use std::time::{Duration, Instant};

use cps::{Instrument, ParentPose, RAD_PER_ARCSEC, observe};
use nalgebra::Isometry3;
use nalgebra::Point3;
use scanner::emulate::geocom::GeoComEmulator;
use scanner::emulate::nmea::NmeaTiltEmulator;
use scanner::emulate::robot::{Body, RobotEmulator};
use scanner::emulate::sick::LmsEmulator;
use scanner::emulate::{Emulator, Faults};
use scanner::protocol::geocom::ReturnCode;
use scanner::serial::Port;
use scanner::serial::geocom::{GeoCom, GeoComConfig};
use scanner::serial::nmea::NmeaTilt;
use scanner::serial::robot::{RobotLink, SerialDrive, SerialHead};
use scanner::serial::sick::{Lms, LmsSettings};
use scanner::sim::{LmsConfig, OdometryError, Robot, SimDrive, SimHead, SimLms, SimTilt, SimWorld, Truth};
use scanner::{
    Drive, HeadKind, PlanarPose, RangeFinder2D, ScanHead, ScannerError, Slice, Target, Tilt, TiltSensor, TotalStation,
};

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
    Target { prism: scanner::Prism::Child(child), predicted: observe(&t.parent, &t.children[child]).expect("reading") }
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
    // Never before its deadlines (no upper bound: a busy machine may be
    // late; the attempts in the error say how many deadlines passed).
    assert!(took >= Duration::from_millis(400), "{took:?}");
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
    // 2° off: no prism in the 1° window, found in the 3° one.
    let (emulator, mut driver) = station(&w, config);
    let exact = driver.measure(&target(&w, 0)).expect("aimed well");
    let mut near = target(&w, 0);
    near.predicted.azimuth_rad += 2f64.to_radians();
    let before = emulator.messages();
    let found = driver.measure(&near).expect("found by the wider search");
    assert_eq!(emulator.messages() - before, 5, "positioning, fine adjust twice, measure, read");
    assert!((found.hz_rad - exact.hz_rad).abs() < 1e-4 && (found.slope_raw_m - exact.slope_raw_m).abs() < 0.01);

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
    // The deadline is 11 periods (220 ms): never before it (no upper bound:
    // a busy machine may be late).
    let took = started.elapsed();
    assert!(took >= Duration::from_millis(220), "{took:?}");
}

fn lms_world() -> SimWorld {
    // Level in the hall, 4 m from the wall at y = 0, the end wall 28 m ahead.
    SimWorld::new(cps::geom::builtin("hall").expect("hall"), ParentPose::new(12.0, 4.0, 1.0, 0.0), vec![])
}

fn sim_lms(w: &SimWorld, sigma: f64) -> SimLms {
    let config = LmsConfig { sigma_range_m: sigma, ..LmsConfig::default() };
    SimLms::new(w.clone(), config, HeadKind::PitchingMount, Isometry3::identity(), 5)
}

fn lms_settings() -> LmsSettings {
    LmsSettings {
        baud: 500_000,
        reply_timeout: Duration::from_millis(300),
        mode_timeout: Duration::from_millis(300),
        baud_settle: Duration::from_millis(20),
        ..LmsSettings::default()
    }
}

/// Checks a slice against the noiseless simulator's (0.5°, mm, 32 m).
fn same_as_sim(slice: &Slice, expected: &Slice) {
    assert_eq!(slice.values.len(), 361);
    assert_eq!((slice.metres_per_count, slice.max_valid, slice.step_rad), (0.001, 0x7FF7, 0.5f64.to_radians()));
    assert_eq!(slice.values, expected.values);
    assert_eq!(slice.range_m(180), Some(28.0));
}

#[test]
fn lms_switches_rate_configures_and_scans_on_request_and_streaming() {
    let w = lms_world();
    let expected = sim_lms(&w, 0.0).scan().expect("sim");
    let emulator = Emulator::spawn(LmsEmulator::new(sim_lms(&w, 0.0))).expect("emulator");
    // The scanner powers on at 9600 Bd with 1°, 8 m: the driver finds it,
    // goes to 500 kBd, 0.5° and the 32 m mode.
    let mut lms = Lms::open(emulator.path(), lms_settings()).expect("connected");
    for _ in 0..3 {
        same_as_sim(&lms.scan().expect("slice"), &expected);
    }
    assert_eq!(lms.discarded, 0);
    drop(lms);
    // Left at 500 kBd, on request: a driver that wants 38400 and a stream
    // finds it at the second candidate rate.
    let settings = LmsSettings { baud: 38400, continuous: true, ..lms_settings() };
    let mut lms = Lms::open(emulator.path(), settings).expect("connected again");
    for _ in 0..3 {
        same_as_sim(&lms.scan().expect("streamed slice"), &expected);
    }
    lms.close().expect("stream stopped, back to 9600");
    drop(lms);
    let mut lms = Lms::open(emulator.path(), LmsSettings { baud: 9600, ..lms_settings() }).expect("at 9600");
    same_as_sim(&lms.scan().expect("slice"), &expected);
}

#[test]
fn lms_recovers_from_every_recoverable_fault() {
    let w = lms_world();
    for continuous in [false, true] {
        for faults in [
            Faults { corrupt_every: Some(3), ..Faults::default() },
            Faults { drop_every: Some(2003), ..Faults::default() },
            Faults { duplicate_every: Some(2011), ..Faults::default() },
            Faults { nak_every: Some(3), ..Faults::default() },
            Faults { delay: Duration::from_millis(50), ..Faults::default() },
        ] {
            let emulator = Emulator::spawn(LmsEmulator::new(sim_lms(&w, 0.005))).expect("emulator");
            let mut lms = Lms::open(emulator.path(), LmsSettings { continuous, ..lms_settings() }).expect("connected");
            emulator.set_faults(faults.clone());
            for _ in 0..8 {
                let slice = lms.scan().unwrap_or_else(|e| panic!("{faults:?}, continuous {continuous}: {e}"));
                let r = slice.range_m(180).expect("the end wall");
                assert!((r - 28.0).abs() < 0.03, "{r}");
            }
            // A stream has no requests to refuse, and a delay loses nothing.
            if faults.delay.is_zero() && !(continuous && faults.nak_every.is_some()) {
                assert!(lms.discarded + lms.retries >= 1, "{faults:?}: the damage was seen");
            }
        }
    }
}

#[test]
fn lms_fails_typed_and_in_time() {
    let w = lms_world();
    let settings = LmsSettings { attempts: 2, ..lms_settings() };
    // A scanner that stops answering: a timeout after 2 × 300 ms.
    let emulator = Emulator::spawn(LmsEmulator::new(sim_lms(&w, 0.0))).expect("emulator");
    let mut lms = Lms::open(emulator.path(), settings).expect("connected");
    emulator.set_faults(Faults { stop_after: Some(emulator.messages()), ..Faults::default() });
    let started = Instant::now();
    let e = lms.scan().expect_err("silent");
    let took = started.elapsed();
    assert!(matches!(e, ScannerError::Timeout { attempts: 2, .. }), "{e}");
    assert!(e.to_string().contains("measured values (30h)"), "{e}");
    assert!(took >= Duration::from_millis(600), "{took:?}");
    // Every request refused: the NAK is the error.
    emulator.set_faults(Faults { nak_every: Some(1), ..Faults::default() });
    let e = lms.scan().expect_err("refused");
    assert!(e.to_string().contains("NAK"), "{e}");
    // The line at another rate: never understood, and not found either
    // when the scanner is stuck at a rate the driver does not try.
    emulator.set_faults(Faults { baud: Some(115_200), ..Faults::default() });
    assert!(matches!(lms.scan(), Err(ScannerError::Timeout { .. })));
    drop(lms);
    let e = Lms::open(emulator.path(), settings).expect_err("not found");
    assert!(e.to_string().contains("any of [500000, 9600, 38400, 19200] Bd"), "{e}");
    // Healthy again: found and scanning.
    emulator.set_faults(Faults::default());
    assert!(Lms::open(emulator.path(), settings).expect("found").scan().is_ok());
}

fn drive_link(path: &str) -> RobotLink {
    RobotLink::new(Port::open("parent drive", path, 115_200).expect("port"), Duration::from_millis(200), 4)
}

/// Moves over the wire equal moves in process (same seed): a retried move
/// is answered from the controller's last reply, never driven twice, under
/// every recoverable fault.
#[test]
fn drives_and_head_move_the_world_once_per_move() {
    let start = PlanarPose { x_m: 2.0, y_m: 4.5, heading_rad: 0.1 };
    let goals: Vec<PlanarPose> =
        (1..=6).map(|k| PlanarPose { x_m: 2.0 + 4.0 * k as f64, y_m: 4.5, heading_rad: 0.1 }).collect();
    let error = OdometryError::default();
    // In process.
    let w = world();
    let mut local = SimDrive::new(w.clone(), Robot::Parent, start, error, 9).expect("drive");
    for g in &goals {
        local.move_to(g).expect("moved");
    }
    let expected = w.truth().parent;
    for faults in [
        Faults::default(),
        Faults { corrupt_every: Some(2), ..Faults::default() },
        Faults { drop_every: Some(151), ..Faults::default() },
        Faults { duplicate_every: Some(157), ..Faults::default() },
        Faults { nak_every: Some(2), ..Faults::default() },
    ] {
        let w = world();
        let sim = SimDrive::new(w.clone(), Robot::Parent, start, error, 9).expect("drive");
        let emulator =
            Emulator::spawn(RobotEmulator::new("parent", Body::Drive(Box::new(sim)), 115_200)).expect("emulator");
        emulator.set_faults(faults.clone());
        let mut drive = SerialDrive::new(drive_link(emulator.path()));
        for g in &goals {
            let odo = drive.move_to(g).unwrap_or_else(|e| panic!("{faults:?}: {e}"));
            assert!((odo.pose.x_m - g.x_m).abs() < 1e-9 && (odo.distance_m - 4.0).abs() < 1e-6, "{odo:?}");
        }
        assert_eq!(w.truth().parent, expected, "{faults:?}");
        drive.relocalise(&start, true).expect("relocalised");
    }
    // The head; a refused angle is the controller's reason, typed.
    let w = world();
    let emulator = Emulator::spawn(RobotEmulator::new(
        "head",
        Body::Head(SimHead::new(w.clone(), HeadKind::RotatingTable)),
        115_200,
    ))
    .expect("emulator");
    let mut head = SerialHead::new(drive_link(emulator.path()), HeadKind::RotatingTable);
    assert_eq!(head.move_to(1.25).expect("turned"), 1.25);
    assert_eq!(w.truth().head_angle_rad, 1.25);
    let e = head.move_to(7.0).expect_err("beyond a turn");
    assert!(matches!(&e, ScannerError::Device { message, .. } if message.contains("0 ≤ angle < 2π")), "{e}");
    // Silence: a typed timeout after 4 × 200 ms.
    emulator.set_faults(Faults { stop_after: Some(emulator.messages()), ..Faults::default() });
    let started = Instant::now();
    let e = head.move_to(2.0).expect_err("silent");
    assert!(matches!(e, ScannerError::Timeout { attempts: 4, .. }), "{e}");
    assert!(started.elapsed() >= Duration::from_millis(800), "{:?}", started.elapsed());
}
