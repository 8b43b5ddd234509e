//! Scan sets registered into one frame ([`fusion::scanset`]) on real
//! points: the three 3DTK scans from their odometry against the reference
//! transforms, and a real scan cut into overlapping parts under known
//! transforms.

use std::path::PathBuf;

use fusion::scanset::{Mode, SetConfig, register_set};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use scanner::io::{from_3dtk_axes, read, read_3dtk_pose, read_matrix4};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data").join(rel)
}

/// (rotation error in degrees, translation error in metres).
fn error(estimate: &Isometry3<f64>, reference: &Isometry3<f64>) -> (f64, f64) {
    let d = reference.inverse() * estimate;
    (d.rotation.angle().to_degrees(), d.translation.vector.norm())
}

fn threedtk(k: usize) -> Vec<Point3<f32>> {
    let c = read(&data(&format!("3dtk_dat/scan{k:03}.3d"))).expect("scan");
    c.points.into_iter().filter(|p| (0.5..32.5).contains(&p.coords.norm())).collect()
}

fn threedtk_reference(a: usize, b: usize) -> Isometry3<f64> {
    from_3dtk_axes(&read_matrix4(&data(&format!("3dtk_dat/reference_T_scan{a:03}_scan{b:03}.txt"))).expect("m"))
}

#[test]
fn the_three_3dtk_scans_land_on_the_references() {
    let scans: Vec<Vec<Point3<f32>>> = (0..3).map(threedtk).collect();
    let starts: Vec<Isometry3<f64>> =
        (0..3).map(|k| read_3dtk_pose(&data(&format!("3dtk_dat/scan{k:03}.pose"))).expect("pose")).collect();
    for mode in [Mode::Graph, Mode::Simultaneous, Mode::Pairwise, Mode::Incremental] {
        let config = SetConfig { mode, ..SetConfig::default() };
        let r = register_set(&scans, &starts, &config, &mut |_, _, _, _| ()).expect("registers");
        assert_eq!(r.world_from_scan[0], starts[0], "the first scan holds the frame");
        for (a, b) in [(0, 1), (1, 2)] {
            let relative = r.world_from_scan[a].inverse() * r.world_from_scan[b];
            let (deg, m) = error(&relative, &threedtk_reference(a, b));
            // The default (graph) within the references' own accuracy; the
            // single strategies land where their matches put them (the
            // seed's simultaneous matching ≈ 1° off on 0←1: README).
            let (max_deg, max_m) = if mode == Mode::Graph { (0.35, 0.03) } else { (1.2, 0.05) };
            assert!(deg < max_deg && m < max_m, "{mode:?} {a}←{b}: {deg}° {m} m");
        }
        assert!(r.unobservable.iter().all(Vec::is_empty), "{mode:?}: {:?}", r.unobservable);
        // The covariances carry the set's variance factor (its three links
        // miss their cycle: σ̂₀² in the hundreds) and, in the single-strategy
        // modes, the poses' departure from the adjustment of their pairs,
        // so they are of the size of the errors against the references (up
        // to 0.35° / 3 cm in graph mode, 1.2° / 5 cm in the others, the
        // second scan 1.05° / 3.9 cm off in simultaneous mode; measured σ
        // 0.51–0.56° / 4–5 cm in graph mode, 0.97–1.23° / 7–11 cm in
        // simultaneous — the second scan's 1° in it — about the first
        // scan's origin), not the matches' own arc seconds.
        for (i, c) in r.covariance.iter().enumerate().skip(1) {
            let (rot, pos) = ((c[(0, 0)] + c[(1, 1)] + c[(2, 2)]).sqrt(), (c[(3, 3)] + c[(4, 4)] + c[(5, 5)]).sqrt());
            assert!(
                rot.is_finite() && rot > 0.05f64.to_radians() && rot < 1.5f64.to_radians(),
                "{mode:?} scan {i}: σ {rot} rad"
            );
            assert!(pos > 0.002 && pos < 0.15, "{mode:?} scan {i}: σ {pos} m");
        }
        // Where the strategy stopped from the adjustment of its pairs:
        // simultaneous mode's 1.05° miss on 0←1 is mostly that (measured
        // 0.83°; graph mode, which is the adjustment, misses by 0.21°).
        if mode == Mode::Graph {
            assert!(r.departure.is_empty(), "{:?}", r.departure);
        } else {
            assert_eq!(r.departure.len(), 3, "{mode:?}");
            assert_eq!(r.departure[0], nalgebra::Vector6::zeros(), "{mode:?}: the first scan holds the frame");
        }
        if mode == Mode::Simultaneous {
            let turn = r.departure[1].fixed_rows::<3>(0).norm().to_degrees();
            assert!(turn > 0.5 && turn < 1.2, "simultaneous scan 1 departs {turn}°");
        }
        if mode == Mode::Graph {
            assert_eq!(r.links.len(), 3, "every pair overlaps: {:?}", r.links.len());
            assert!(
                r.links.iter().all(|l| l.rejected.is_none()),
                "{:?}",
                r.links.iter().map(|l| &l.rejected).collect::<Vec<_>>()
            );
        }
    }
}

/// Scan 1 cut into four overlapping parts — each a different half of its
/// points, drawn by a hash — each kept in its own frame under a known
/// transform (turned about the scanner, which stays at each frame's
/// origin as in a real scan); the starts off by up to 0.5 m and 5°: every
/// part comes back to 0.1° / 1 cm of the truth. (Parts cut by azimuth
/// into wedges are not used: this scan leaves out the quarter behind its
/// robot. Wedges of the room scan are, below.)
#[test]
fn a_real_scan_cut_into_parts_comes_back_together() {
    let points = threedtk(1);
    let truth: Vec<Isometry3<f64>> = (0..4)
        .map(|k| {
            let k = k as f64;
            Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_euler_angles(0.02 * k, -0.01 * k, 0.4 * k),
            )
        })
        .collect();
    let parts: Vec<Vec<Point3<f32>>> = (0..4u64)
        .map(|k| {
            points
                .iter()
                .enumerate()
                .filter(|(i, _)| (((*i as u64) ^ (k << 32)).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 63) == 0)
                .map(|(_, p)| (truth[k as usize].inverse() * p.cast::<f64>()).cast::<f32>())
                .collect()
        })
        .collect();
    for (k, p) in parts.iter().enumerate() {
        assert!((0.45..0.55).contains(&(p.len() as f64 / points.len() as f64)), "part {k}: {} points", p.len());
    }
    let offsets = [
        (Vector3::<f64>::zeros(), Vector3::<f64>::zeros()),
        (Vector3::new(0.5, 0.0, 0.0), Vector3::new(0.0, 0.0, 5.0)),
        (Vector3::new(-0.3, 0.4, 0.0), Vector3::new(2.0, -3.0, -4.0)),
        (Vector3::new(0.0, -0.35, 0.35), Vector3::new(-3.0, 3.0, 2.5)),
    ];
    let starts: Vec<Isometry3<f64>> = truth
        .iter()
        .zip(offsets)
        .map(|(t, (dt, dr))| {
            let r = UnitQuaternion::from_euler_angles(dr.x.to_radians(), dr.y.to_radians(), dr.z.to_radians());
            Isometry3::from_parts(Translation3::from(dt), r) * t
        })
        .collect();
    for mode in [Mode::Graph, Mode::Simultaneous] {
        let config = SetConfig { mode, ..SetConfig::default() };
        let r = register_set(&parts, &starts, &config, &mut |_, _, _, _| ()).expect("registers");
        for (k, (pose, truth)) in r.world_from_scan.iter().zip(&truth).enumerate().skip(1) {
            let (deg, m) = error(pose, truth);
            assert!(deg < 0.1 && m < 0.01, "{mode:?} part {k}: {deg}° {m} m");
        }
    }
}

/// The PCL room's first scan (360°) cut into three 180° wedges every 120°
/// — each overlapping its neighbours by 60° — each in its own frame turned
/// about the scanner; the starts 3° and 6 cm off. The defaults (the
/// coarse-to-fine schedule, Huber 2 cm, the link graph matched both ways)
/// bring every wedge back within 0.1° / 1 cm, and with only the pairs the
/// target covers within 0.02° / 2 mm, where a single scale at 0.1 m / 1 m without a
/// kernel (plain `register`'s defaults) lands degrees off: points beyond
/// one wedge's edge pair with the other's edge and pull.
#[test]
fn overlapping_wedges_of_a_real_room_scan_come_back_together() {
    let points = read(&data("pcl_room_scans/room_scan1.pcd")).expect("scan").points;
    let truth: Vec<Isometry3<f64>> = (0..3)
        .map(|k| {
            let yaw = (120.0 * k as f64).to_radians();
            Isometry3::from_parts(Translation3::identity(), UnitQuaternion::from_euler_angles(0.0, 0.0, yaw))
        })
        .collect();
    let wedges: Vec<Vec<Point3<f32>>> = truth
        .iter()
        .map(|t| {
            let centre = t.rotation.euler_angles().2;
            points
                .iter()
                .filter(|p| {
                    let a = f64::from(p.y).atan2(f64::from(p.x)) - centre;
                    a.sin().atan2(a.cos()).abs() <= 90f64.to_radians()
                })
                .map(|p| (t.inverse() * p.cast::<f64>()).cast::<f32>())
                .collect()
        })
        .collect();
    let off = Isometry3::from_parts(
        Translation3::new(0.05, -0.03, 0.0),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 3f64.to_radians()),
    );
    let starts: Vec<Isometry3<f64>> =
        truth.iter().enumerate().map(|(k, t)| if k == 0 { *t } else { off * t }).collect();
    let r = register_set(&wedges, &starts, &SetConfig::default(), &mut |_, _, _, _| ()).expect("registers");
    for (k, (pose, truth)) in r.world_from_scan.iter().zip(&truth).enumerate().skip(1) {
        let (deg, m) = error(pose, truth);
        assert!(deg < 0.1 && m < 0.01, "wedge {k}: {deg}° {m} m");
    }
    // Where a wedge ends, its neighbour's points beyond the cut pair with
    // the cut's edge: left out (`only_covered`), the wedges come back
    // within 0.011° / 1.3 mm; kept, and matched one way, 0.025° / 3.5 mm.
    let worst = |r: &fusion::scanset::SetResult| {
        (1..3).map(|k| error(&r.world_from_scan[k], &truth[k])).fold((0.0, 0.0), |(d, m), (a, b)| (a.max(d), b.max(m)))
    };
    let covered = SetConfig { only_covered: true, ..SetConfig::default() };
    let c = register_set(&wedges, &starts, &covered, &mut |_, _, _, _| ()).expect("registers");
    let (deg, m) = worst(&c);
    assert!(deg < 0.02 && m < 0.002, "{deg}° {m} m");
    let mut edges = SetConfig::default();
    edges.link.both_ways = false;
    let e = register_set(&wedges, &starts, &edges, &mut |_, _, _, _| ()).expect("registers");
    assert!(worst(&e).1 > 2.0 * m, "with the edges' pairs, one way: {:?} against {deg}° {m} m", worst(&e));
    let plain = SetConfig {
        mode: Mode::Pairwise,
        stages: vec![fusion::icp::Stage { voxel_m: 0.1, max_correspondence_m: 1.0 }],
        link: fusion::links::LinkConfig {
            multiview: fusion::multiview::MultiviewConfig {
                icp: fusion::icp::IcpConfig {
                    kernel: fusion::icp::Kernel::None,
                    ..SetConfig::default().link.multiview.icp
                },
                ..SetConfig::default().link.multiview
            },
            ..SetConfig::default().link
        },
        viewpoints: Vec::new(),
        only_covered: false,
    };
    let r = register_set(&wedges, &starts, &plain, &mut |_, _, _, _| ()).expect("registers");
    let worst = (1..3).map(|k| error(&r.world_from_scan[k], &truth[k]).0).fold(0.0, f64::max);
    assert!(worst > 1.0, "a single plain scale lands {worst}° off (the contrast the defaults are for)");
}

/// Point-to-point on two scans of one straight line (no blind-direction
/// analysis): the turn about the line is unseen, the match's information
/// singular — the scan's covariance is still finite, the start's step σ
/// about the line and the match's along it.
#[test]
fn a_match_that_cannot_see_a_turn_gets_the_start_step_there() {
    use fusion::icp::{Method, Stage};
    let line: Vec<Point3<f32>> = (0..1000).map(|k| Point3::new(k as f32 * 0.01, 0.0, 0.0)).collect();
    let shifted: Vec<Point3<f32>> = line.iter().map(|p| p - Vector3::new(0.02, 0.0, 0.0)).collect();
    let mut config = SetConfig {
        mode: Mode::Pairwise,
        stages: vec![Stage { voxel_m: 0.05, max_correspondence_m: 0.5 }],
        ..SetConfig::default()
    };
    let icp = &mut config.link.multiview.icp;
    icp.method = Method::PointToPoint;
    icp.reject_back_faces = false;
    icp.degeneracy_ratio = None;
    config.link.multiview.min_pairs = 50;
    let starts = [Isometry3::identity(); 2];
    let r = register_set(&[line, shifted], &starts, &config, &mut |_, _, _, _| ()).expect("registers");
    let m = r.links[0].result.as_ref().expect("the match");
    assert!(m.information.try_inverse().is_none() || m.information[(0, 0)].abs() < 1e-9, "{}", m.information);
    let c = r.covariance[1];
    assert!(c.iter().all(|v| v.is_finite()), "{c}");
    let step = config.link.step_sigma_rad.powi(2);
    assert!((c[(0, 0)] - step).abs() < 1e-6 * step, "σ² about the line {} vs the step's {step}", c[(0, 0)]);
    assert!(c[(3, 3)] > 0.0 && c[(3, 3)] < 1e-4, "along the line the match's: {}", c[(3, 3)]);
}

/// Point-to-plane on two scans of one pipe (a cylinder along x, r 1.5 m,
/// 20 m long, 1 mm noise), placed pairwise: the slide along the axis and
/// the roll about it are unseen — the scan's covariance there is the
/// start's step σ, along the seen directions its match's covariance by
/// range (sub-millimetre), and it stays finite.
#[test]
fn a_pipe_placed_pairwise_gets_the_start_step_along_its_axis() {
    use fusion::icp::Stage;
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut pipe = |frame: &Isometry3<f64>| -> Vec<Point3<f32>> {
        (0..20_000)
            .map(|_| {
                let (x, a): (f64, f64) = (rng.random_range(0.0..20.0), rng.random_range(0.0..std::f64::consts::TAU));
                let r = 1.5 + 0.001 * (rng.random::<f64>() - 0.5) * 3.46;
                (frame.inverse() * Point3::new(x, r * a.cos(), r * a.sin())).cast::<f32>()
            })
            .collect()
    };
    let truth = Isometry3::translation(0.0, 0.01, -0.005);
    let scans = [pipe(&Isometry3::identity()), pipe(&truth)];
    let starts = [Isometry3::identity(), Isometry3::translation(0.02, 0.0, 0.0) * truth];
    let config = SetConfig {
        mode: Mode::Pairwise,
        stages: vec![Stage { voxel_m: 0.05, max_correspondence_m: 0.3 }],
        ..SetConfig::default()
    };
    let r = register_set(&scans, &starts, &config, &mut |_, _, _, _| ()).expect("registers");
    assert_eq!(r.unobservable[1].len(), 2, "{:?}", r.unobservable[1]);
    let c = r.covariance[1];
    assert!(c.iter().all(|v| v.is_finite()), "{c}");
    let (rad, m) = (config.link.step_sigma_rad.powi(2), config.link.step_sigma_m.powi(2));
    assert!((c[(0, 0)] - rad).abs() < 1e-3 * rad, "σ² of the roll {} against the step's {rad}", c[(0, 0)]);
    assert!((c[(3, 3)] - m).abs() < 1e-3 * m, "σ² along the axis {} against the step's {m}", c[(3, 3)]);
    for k in [1, 2, 4, 5] {
        assert!(c[(k, k)] > 0.0 && c[(k, k)] < 1e-6, "seen direction {k}: σ² {}", c[(k, k)]);
    }
}

/// Georeferenced starts — the 3DTK set moved 5,400 km north and turned 30°
/// (UTM-like coordinates, where f32 keeps half a metre) — register exactly
/// as in the scans' own frame: every pose moved by the same transform to a
/// micrometre, in graph and pairwise mode, with the covariances turned
/// into the world's axes (the same σ as at the origin).
#[test]
fn georeferenced_starts_register_as_local_ones() {
    let scans: Vec<Vec<Point3<f32>>> = (0..3).map(threedtk).collect();
    let starts: Vec<Isometry3<f64>> =
        (0..3).map(|k| read_3dtk_pose(&data(&format!("3dtk_dat/scan{k:03}.pose"))).expect("pose")).collect();
    let utm = Isometry3::from_parts(
        Translation3::new(512_345.678, 5_400_123.456, 312.5),
        UnitQuaternion::from_euler_angles(0.0, 0.0, 30f64.to_radians()),
    );
    let far: Vec<Isometry3<f64>> = starts.iter().map(|s| utm * s).collect();
    for mode in [Mode::Graph, Mode::Pairwise] {
        let config = SetConfig { mode, ..SetConfig::default() };
        let near = register_set(&scans, &starts, &config, &mut |_, _, _, _| ()).expect("local");
        let r = register_set(&scans, &far, &config, &mut |_, _, _, _| ()).expect("georeferenced");
        assert_eq!(r.world_from_scan[0], far[0], "{mode:?}: the first scan holds the frame");
        for (k, (a, b)) in near.world_from_scan.iter().zip(&r.world_from_scan).enumerate() {
            let d = (utm * a).inverse() * b;
            assert!(d.translation.vector.norm() < 1e-6 && d.rotation.angle() < 1e-8, "{mode:?} scan {k}: {d}");
        }
        // Covariances in the world's axes about the first scan's origin:
        // the local ones turned by the rotation alone, so the position σ is
        // the same at UTM (carried to the world's origin, the rotations'
        // lever arm over 5,400 km made it hundreds of metres).
        let ad = fusion::se3::adjoint(&Isometry3::from_parts(Translation3::identity(), utm.rotation));
        for (k, (a, b)) in near.covariance.iter().zip(&r.covariance).enumerate() {
            let moved = ad * a * ad.transpose();
            assert!((moved - b).amax() <= 1e-6 * moved.amax().max(1e-30), "{mode:?} scan {k}: {b} vs {moved}");
            let sigma = |c: &nalgebra::Matrix6<f64>| c.fixed_view::<3, 3>(3, 3).trace().sqrt();
            assert!((sigma(a) - sigma(b)).abs() <= 1e-6 * sigma(a).max(1e-12), "{mode:?} scan {k}: σxyz");
            assert!(sigma(b) < 0.1, "{mode:?} scan {k}: σxyz {} m at UTM", sigma(b));
        }
        assert!(near.unobservable.iter().chain(&r.unobservable).all(Vec::is_empty));
    }
}

/// The finest stage of the 3DTK schedule as the verification matches:
/// 5 cm cells, 0.2 m reach.
fn finest_3dtk_link() -> fusion::links::LinkConfig {
    let base = fusion::links::LinkConfig::default();
    fusion::links::LinkConfig {
        multiview: fusion::multiview::MultiviewConfig {
            source_voxel_m: 0.05,
            target_voxel_m: 0.05,
            icp: fusion::icp::IcpConfig { max_correspondence_m: 0.2, ..base.multiview.icp },
            ..base.multiview
        },
        ..base
    }
}

/// The verification's matches say how far they use the same part of each
/// scan — the footprint overlap by which the modes without a link graph
/// weigh a scan's noise common to its matches: all of it for disjoint
/// thirds of one real scan dealt point by point (every match uses the
/// whole scan); none for the middle one of three 100° wedges of it 70°
/// apart, which overlaps its two neighbours on opposite sides (the scan
/// spans −120° to 90° of azimuth: the outer two do not meet, and a scan
/// with one match has nothing to share it with: 1).
#[test]
fn the_verifications_matches_share_the_thirds_footprints_and_not_a_wedges() {
    use fusion::verify::check_pairs;
    let config = finest_3dtk_link();
    let (truth, thirds) = thirds_of_a_3dtk_scan();
    let shared = check_pairs(&thirds, &truth, &[None; 3], &config, 0.05).expect("checked").shared;
    assert!(shared.iter().all(|&s| s > 0.8), "thirds: {shared:?}");
    let points = threedtk(1);
    let wedges: Vec<Vec<Point3<f32>>> = [-70f32, 0.0, 70.0]
        .iter()
        .map(|centre| {
            points
                .iter()
                .filter(|p| {
                    let d = p.y.atan2(p.x) - centre.to_radians();
                    d.sin().atan2(d.cos()).abs() <= 50f32.to_radians()
                })
                .copied()
                .collect()
        })
        .collect();
    let checked = check_pairs(&wedges, &[Isometry3::identity(); 3], &[None; 3], &config, 0.05).expect("checked");
    let pairs: Vec<(usize, usize)> = checked.pairs.iter().map(|c| (c.target, c.source)).collect();
    assert_eq!(pairs, [(0, 1), (1, 2)], "the middle wedge overlaps both others");
    assert!(checked.shared[1] < 0.2, "wedges: {:?}", checked.shared);
    assert_eq!((checked.shared[0], checked.shared[2]), (1.0, 1.0), "wedges: {:?}", checked.shared);
}

/// Disjoint thirds of 3DTK scan 1 (each point dealt to one at random),
/// each under a known transform: (the transforms, the thirds in their own
/// frames). Not every third point: thirds interleaved along the scan lines
/// are a little more alike than two scans' samples (registered, a pair's
/// RMS residual 15.0 mm; dealt at random 15.6–16.0 mm).
fn thirds_of_a_3dtk_scan() -> (Vec<Isometry3<f64>>, Vec<Vec<Point3<f32>>>) {
    let points = threedtk(1);
    let truth: Vec<Isometry3<f64>> = (0..3)
        .map(|k| {
            let k = k as f64;
            Isometry3::from_parts(
                Translation3::new(0.2 * k, -0.1 * k, 0.0),
                UnitQuaternion::from_euler_angles(0.01 * k, 0.02 * k, 0.5 * k),
            )
        })
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut shares: Vec<Vec<Point3<f32>>> = vec![Vec::new(); 3];
    for p in &points {
        let k = rng.random_range(0..3);
        shares[k].push((truth[k].inverse() * p.cast::<f64>()).cast::<f32>());
    }
    (truth, shares)
}

/// The verification's residual against the data's noise: each check
/// reports its match's RMS residual and the pair's noise floor (two random
/// halves of each scan matched at the identity). Disjoint random thirds
/// of one real scan registered under known transforms leave a little
/// less than the floor (measured 0.81–0.82×: the floor's halves are
/// halves of each third, sparser than the thirds); the three 3DTK scans,
/// taken from different places, leave several times it at their right
/// poses (measured 2.8–3.3×: other samplings, incidence and occlusions)
/// — which is why the ratio is reported, not judged. (With the floor's
/// halves drawn by two multiplicative hashes, which shared 29 % of the
/// points, and the thirds every third point, 1.30–1.32× and 4.4–5.3×.)
#[test]
fn the_checks_report_the_residual_against_the_noise_floor() {
    let (truth, shares) = thirds_of_a_3dtk_scan();
    let r = register_set(&shares, &truth, &SetConfig::default(), &mut |_, _, _, _| ()).expect("registers");
    assert_eq!(r.checks.len(), 3, "every pair overlaps");
    for c in &r.checks {
        let ratio = c.rmse_m.expect("matched") / c.noise_m;
        assert!(c.noise_m > 0.005 && c.noise_m < 0.03, "floor {} m", c.noise_m);
        assert!((0.6..1.1).contains(&ratio), "{}←{}: {ratio}", c.target, c.source);
    }
    let scans: Vec<Vec<Point3<f32>>> = (0..3).map(threedtk).collect();
    let starts: Vec<Isometry3<f64>> =
        (0..3).map(|k| read_3dtk_pose(&data(&format!("3dtk_dat/scan{k:03}.pose"))).expect("pose")).collect();
    let r = register_set(&scans, &starts, &SetConfig::default(), &mut |_, _, _, _| ()).expect("registers");
    for c in &r.checks {
        let ratio = c.rmse_m.expect("matched") / c.noise_m;
        assert!((2.0..5.0).contains(&ratio), "{}←{}: {ratio}", c.target, c.source);
    }
}

/// Issue 38, a pair that finds a much closer fit nearby disagrees with the
/// poses, however little it moves: disjoint thirds of a real scan under
/// known transforms, checked at their true poses and with one third
/// shifted 0.15 m — 4 % of its RMS radius, within the motion tiers
/// (5 % along what a pair sees well, 20 % in all), as the NEES bench's
/// street wedge placed 0.29 m along the street by a link still creeping at
/// its cap was (8.9 %, exit 0). Matched again from the shifted poses, its
/// pairs settle back where their residual is several times lower
/// (measured 3.3×; the wedge's 3.4×); at the true poses they stay
/// (within 1.001×).
#[test]
fn a_pair_that_finds_a_much_closer_fit_nearby_disagrees_with_the_poses() {
    use fusion::verify::{MAX_RESIDUAL_GAIN, check_pairs, untrusted};
    let (truth, shares) = thirds_of_a_3dtk_scan();
    let config = finest_3dtk_link();
    let gain = |c: &fusion::verify::PairCheck| c.start_rmse_m.expect("matched") / c.rmse_m.expect("matched");
    let right = check_pairs(&shares, &truth, &[None; 3], &config, 0.05).expect("checked").pairs;
    assert_eq!(right.len(), 3, "every pair overlaps");
    for c in &right {
        assert!(c.consistent && gain(c) < 1.1, "{}←{} at the truth: gain {}, {c:?}", c.target, c.source, gain(c));
    }
    let mut off = truth.clone();
    off[2] = Translation3::new(0.15, 0.0, 0.0) * truth[2];
    let checks = check_pairs(&shares, &off, &[None; 3], &config, 0.05).expect("checked").pairs;
    for c in checks.iter().filter(|c| c.source == 2 || c.target == 2) {
        let relative = c.relative_motion.expect("matched");
        assert!(relative < 0.05 && c.angle_rad.expect("matched") < 0.01, "{}←{}: {relative}", c.target, c.source);
        assert!(gain(c) > 2.0 * MAX_RESIDUAL_GAIN, "{}←{}: gain {}", c.target, c.source, gain(c));
        assert!(!c.consistent, "{}←{}", c.target, c.source);
    }
    assert_eq!(untrusted(3, &checks), [2]);
}
