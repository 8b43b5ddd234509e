//! Constraint checks on every step of a schedule ([`Dance::steps`]): the
//! total station's range, line of sight at measurement time and during
//! tracked motion, slope, robot clearance from the scene and from each other,
//! and the scanner's range at scan stations.

use nalgebra::{Point3, Vector3};

use cps::geom::{Ray, Scene};

use crate::dance::{Action, Dance, Robot, Step};

/// The limits a plan is checked against.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Total station's shortest measurable slope distance, metres.
    pub min_range_m: f64,
    /// Total station's longest slope distance (or longest sight line the
    /// mission allows), metres.
    pub max_range_m: f64,
    /// Steepest move a robot may drive, radians (`None`: unchecked).
    pub max_slope_rad: Option<f64>,
    /// Radius of a robot's footprint: its clearance from the scene and half
    /// its distance to another robot, metres (`None`: unchecked).
    pub footprint_radius_m: Option<f64>,
    /// The standing robot keeps its sight line to the moving one during every
    /// move (a child tracked by the parent's total station; the moving
    /// parent's sight lines to the standing children).
    pub track: bool,
    /// Scanner's longest range, metres (`None`: unchecked): a scan station
    /// must have a surface within it, and lie within it of the previous scan
    /// station so consecutive scans overlap.
    pub scanner_max_range_m: Option<f64>,
}

impl Limits {
    /// Range limits only (no scene checks).
    pub fn range(min_range_m: f64, max_range_m: f64) -> Self {
        Self {
            min_range_m,
            max_range_m,
            max_slope_rad: None,
            footprint_radius_m: None,
            track: false,
            scanner_max_range_m: None,
        }
    }
}

/// Distance between samples along a move (tracking, clearance), metres.
pub const SWEEP_STEP_M: f64 = 0.25;

/// What a violation breaks.
#[derive(Debug, Clone, PartialEq)]
pub enum Check {
    /// A sight line outside the total station's range (value: slope
    /// distance; limit: the bound it crosses).
    Range,
    /// A sight line blocked at measurement time (value: distance from the
    /// instrument to the obstacle).
    LineOfSight {
        /// Name of the blocking scene object.
        obstacle: String,
    },
    /// A sight line lost while a robot moves (value: distance driven when
    /// it is lost).
    Tracking {
        /// Name of the blocking scene object.
        obstacle: String,
        /// The robot whose sight line is lost (the other end of the line).
        target: Robot,
    },
    /// A move steeper than allowed (value and limit: slope, radians).
    Slope,
    /// A robot closer to the scene than its footprint (value: clearance;
    /// limit: footprint radius).
    Clearance {
        /// Name of the nearest scene object.
        obstacle: String,
    },
    /// Two robots closer than two footprint radii (value: distance).
    Separation {
        /// The other robot.
        other: Robot,
    },
    /// A scan station with no surface within the scanner's range (value:
    /// distance to the nearest surface).
    ScanNothingInRange,
    /// A scan station farther than the scanner's range from the previous
    /// one (value: distance), so the scans cannot overlap.
    ScanGap {
        /// The previous scan station.
        previous: usize,
    },
}

impl Check {
    /// The check's short name: `range`, `line-of-sight`, `tracking`,
    /// `slope`, `clearance`, `separation`, `scan-nothing-in-range`,
    /// `scan-gap`.
    pub fn name(&self) -> &'static str {
        match self {
            Check::Range => "range",
            Check::LineOfSight { .. } => "line-of-sight",
            Check::Tracking { .. } => "tracking",
            Check::Slope => "slope",
            Check::Clearance { .. } => "clearance",
            Check::Separation { .. } => "separation",
            Check::ScanNothingInRange => "scan-nothing-in-range",
            Check::ScanGap { .. } => "scan-gap",
        }
    }
}

/// One broken constraint.
#[derive(Debug, Clone, PartialEq)]
pub struct Violation {
    /// Index of the step in [`Dance::steps`].
    pub step: usize,
    /// Dance cycle of the step (0: before the first).
    pub cycle: usize,
    /// The robot the step is about (the moving or measured one; the parent
    /// for fixes, parent moves and scans).
    pub robot: Robot,
    /// The parent's station during the step.
    pub station: usize,
    /// What is broken.
    pub check: Check,
    /// The offending value (metres or radians, see [`Check`]).
    pub value: f64,
    /// The limit it breaks (same unit).
    pub limit: f64,
}

impl Violation {
    /// Where it happens: the moving child's destination or the measured
    /// child, else the parent's station during the step (the station
    /// reached, for a parent move). `steps` are the dance's
    /// [`Dance::steps`].
    pub fn position(&self, dance: &Dance, steps: &[crate::dance::Step]) -> Point3<f64> {
        let here = match steps.get(self.step).map(|s| &s.action) {
            Some(Action::MoveChild { to, .. }) => Some(*to),
            Some(Action::Measure { child, .. }) => dance.child_at(self.cycle, *child),
            _ => None,
        };
        here.or_else(|| dance.stations.get(self.station).map(|s| s.position)).unwrap_or_else(Point3::origin)
    }

    /// A sentence naming the step, the robots, the constraint and the value;
    /// `name` names a robot.
    pub fn describe(&self, name: &dyn Fn(Robot) -> String) -> String {
        let who = name(self.robot);
        let what = match &self.check {
            Check::Range => format!(
                "the sight line to {who} from station {} is {:.3} m long; the total station's range ends at {} m",
                self.station, self.value, self.limit
            ),
            Check::LineOfSight { obstacle } => format!(
                "the sight line from the parent at station {} to {who} is blocked by \"{obstacle}\" {:.2} m from the instrument",
                self.station, self.value
            ),
            Check::Tracking { obstacle, target } => format!(
                "{who} loses sight of {} behind \"{obstacle}\" after {:.2} m of its move",
                name(*target),
                self.value
            ),
            Check::Slope => format!(
                "{who}'s move climbs at {:.1}°; the limit is {:.1}°",
                self.value.to_degrees(),
                self.limit.to_degrees()
            ),
            Check::Clearance { obstacle } => format!(
                "{who} comes within {:.2} m of \"{obstacle}\"; its footprint needs {:.2} m",
                self.value, self.limit
            ),
            Check::Separation { other } => format!(
                "{who} stands {:.2} m from {}; two footprints need {:.2} m",
                self.value,
                name(*other),
                self.limit
            ),
            Check::ScanNothingInRange => format!(
                "the scan at station {} has no surface within the scanner's {} m (nearest {:.1} m)",
                self.station, self.limit, self.value
            ),
            Check::ScanGap { previous } => format!(
                "the scan at station {} is {:.1} m from the previous scan (station {previous}); \
                 the scanner's range is {} m, so the scans cannot overlap",
                self.station, self.value, self.limit
            ),
        };
        format!("step {} (cycle {}): {what}", self.step, self.cycle)
    }
}

/// Checks every step of `dance` against `limits`, and against `scene` when
/// given (line of sight, tracking, clearance, scan ranges); returns the
/// violations in schedule order. Each move reports at most one clearance and
/// one tracking violation per sight line (the first sample that breaks it).
pub fn check(dance: &Dance, scene: Option<&Scene>, limits: &Limits, scan_at: impl Fn(usize) -> bool) -> Vec<Violation> {
    check_steps(dance, &dance.steps(scan_at), scene, limits)
}

/// [`check`] of the schedule's `steps` ([`Dance::steps`]) already built.
pub fn check_steps(dance: &Dance, steps: &[Step], scene: Option<&Scene>, limits: &Limits) -> Vec<Violation> {
    let mut out = Vec::new();
    let n = dance.n_children();
    // Where every child stands before each step (None: not yet placed).
    let mut children: Vec<Option<Point3<f64>>> = vec![None; n];
    let mut previous_scan: Option<usize> = None;
    for step in steps {
        let v = |robot, station, check, value, limit| Violation {
            step: step.index,
            cycle: step.cycle,
            robot,
            station,
            check,
            value,
            limit,
        };
        match &step.action {
            Action::MoveChild { child, from, to } => {
                let robot = Robot::Child(*child);
                let station = dance.cycles[step.cycle - 1].from;
                let parent = (Robot::Parent, dance.stations[station].position);
                children[*child] = Some(*to);
                let others: Vec<_> =
                    std::iter::once(parent).chain(placed(&children)).filter(|(o, _)| *o != robot).collect();
                for (check, value, limit) in move_checks(from, to, &[parent], &others, scene, limits) {
                    out.push(v(robot, station, check, value, limit));
                }
            }
            Action::Measure { child, station, .. } => {
                let robot = Robot::Child(*child);
                let (Some(prism), parent) = (children[*child], dance.stations[*station].position) else {
                    continue;
                };
                let range = (prism - parent).norm();
                if range < limits.min_range_m {
                    out.push(v(robot, *station, Check::Range, range, limits.min_range_m));
                } else if range > limits.max_range_m {
                    out.push(v(robot, *station, Check::Range, range, limits.max_range_m));
                }
                if let Some(scene) = scene
                    && let Some(hit) = scene.obstruction(&parent, &prism)
                {
                    let obstacle = scene.object_name(hit.object).to_string();
                    out.push(v(robot, *station, Check::LineOfSight { obstacle }, hit.distance_m, range));
                }
            }
            Action::MoveParent { from, to } => {
                let (a, b) = (dance.stations[*from].position, dance.stations[*to].position);
                let standing: Vec<_> = placed(&children).collect();
                for (check, value, limit) in move_checks(&a, &b, &standing, &standing, scene, limits) {
                    out.push(v(Robot::Parent, *to, check, value, limit));
                }
            }
            // Control is sighted only where it is visible and in range
            // (`crate::sighting::sightings`): nothing to break.
            Action::Fix { .. } | Action::Sight { .. } => {}
            Action::Scan { station } => {
                let (Some(max), p) = (limits.scanner_max_range_m, dance.stations[*station].position) else {
                    continue;
                };
                if let Some(scene) = scene {
                    let (d, _) = scene.distance(&p);
                    if d > max {
                        out.push(v(Robot::Parent, *station, Check::ScanNothingInRange, d, max));
                    }
                }
                if let Some(prev) = previous_scan {
                    let d = (p - dance.stations[prev].position).norm();
                    if d > max {
                        out.push(v(Robot::Parent, *station, Check::ScanGap { previous: prev }, d, max));
                    }
                }
                previous_scan = Some(*station);
            }
        }
    }
    out
}

/// The placed children with their positions.
fn placed(children: &[Option<Point3<f64>>]) -> impl Iterator<Item = (Robot, Point3<f64>)> + '_ {
    children.iter().enumerate().filter_map(|(j, p)| Some((Robot::Child(j), (*p)?)))
}

/// The checks of one robot's move a → b, as (check, value, limit): its
/// slope; its clearance from the scene; with `track`, its sight line to each
/// of `targets` (the robots it stays locked on); its separation at b from
/// `others` (the robots standing).
fn move_checks(
    a: &Point3<f64>,
    b: &Point3<f64>,
    targets: &[(Robot, Point3<f64>)],
    others: &[(Robot, Point3<f64>)],
    scene: Option<&Scene>,
    limits: &Limits,
) -> Vec<(Check, f64, f64)> {
    let mut out = Vec::new();
    if let Some(slope) = slope_violation(a, b, limits) {
        out.push((Check::Slope, slope, limits.max_slope_rad.unwrap_or(0.0)));
    }
    if let Some(scene) = scene {
        if let Some((value, limit, obstacle)) = sweep_clearance(scene, a, b, limits) {
            out.push((Check::Clearance { obstacle }, value, limit));
        }
        if limits.track {
            for &(target, at) in targets {
                if let Some((driven, obstacle)) = sweep_sight(scene, a, b, &at) {
                    out.push((Check::Tracking { obstacle, target }, driven, 0.0));
                }
            }
        }
    }
    if let Some(r) = limits.footprint_radius_m {
        for &(other, p) in others {
            let d = (p.xy() - b.xy()).norm();
            if d < 2.0 * r {
                out.push((Check::Separation { other }, d, 2.0 * r));
            }
        }
    }
    out
}

/// The slope of the move a → b when steeper than the limit.
fn slope_violation(a: &Point3<f64>, b: &Point3<f64>, limits: &Limits) -> Option<f64> {
    let max = limits.max_slope_rad?;
    let d = b - a;
    let slope = d.z.abs().atan2(d.xy().norm());
    (slope > max + 1e-12).then_some(slope)
}

/// Points every [`SWEEP_STEP_M`] from a to b, both ends included, with the
/// distance driven.
fn sweep(a: &Point3<f64>, b: &Point3<f64>) -> impl Iterator<Item = (f64, Point3<f64>)> {
    let d = b - a;
    let len = d.norm();
    let n = (len / SWEEP_STEP_M).ceil().max(1.0) as usize;
    let a = *a;
    (0..=n).map(move |i| {
        let t = i as f64 / n as f64;
        (t * len, a + t * d)
    })
}

/// The first sample of the move a → b whose sight line to `target` is
/// blocked: (distance driven, obstacle).
fn sweep_sight(scene: &Scene, a: &Point3<f64>, b: &Point3<f64>, target: &Point3<f64>) -> Option<(f64, String)> {
    sweep(a, b)
        .find_map(|(at, p)| scene.obstruction(&p, target).map(|hit| (at, scene.object_name(hit.object).to_string())))
}

/// The smallest clearance along the move a → b when it is below the
/// footprint radius: (clearance, radius, obstacle).
fn sweep_clearance(scene: &Scene, a: &Point3<f64>, b: &Point3<f64>, limits: &Limits) -> Option<(f64, f64, String)> {
    let r = limits.footprint_radius_m?;
    let mut worst: Option<(f64, usize)> = None;
    for (_, p) in sweep(a, b) {
        let (d, object) = clearance(scene, &p, r);
        if d < r && worst.is_none_or(|(w, _)| d < w) {
            worst = Some((d, object));
        }
    }
    worst.map(|(d, object)| (d, r, scene.object_name(object).to_string()))
}

/// Clearance of a robot of footprint radius `r` whose instrument (or prism)
/// is at `p`: the robot is a column of spheres of radius `r` from just above
/// the ground below `p` up to `p`; returns the smallest distance from a
/// sphere centre to the scene, and the nearest object. The ground is the
/// first surface straight below `p` (a robot above a crate stands on it).
pub fn clearance(scene: &Scene, p: &Point3<f64>, r: f64) -> (f64, usize) {
    let down = Ray::new(*p, -Vector3::z()).ok().and_then(|ray| scene.cast(&ray, 100.0));
    let lowest = match down {
        Some(hit) => hit.point.z + r + 0.02,
        None => p.z,
    };
    let mut best = scene.distance(p);
    let mut z = lowest;
    while z < p.z {
        let d = scene.distance(&Point3::new(p.x, p.y, z));
        if d.0 < best.0 {
            best = d;
        }
        z += r.max(0.05);
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Phase;
    use crate::{Strategy, schedule, stations};
    use cps::geom::SceneBuilder;

    fn scene_with_pillar() -> Scene {
        let mut b = SceneBuilder::new();
        b.cuboid("floor", Point3::new(20.0, 0.0, -0.05), Vector3::new(60.0, 40.0, 0.1), 0.0).expect("floor");
        b.cylinder("pillar", Point3::new(10.0, 2.0, 0.0), Point3::new(10.0, 2.0, 4.0), 0.4).expect("pillar");
        b.build("test")
    }

    fn dance(strategy: Strategy) -> Dance {
        let route = [Point3::new(0.0, 0.0, 1.5), Point3::new(20.0, 0.0, 1.5)];
        let formation = [Vector3::new(4.0, 4.0, -0.5), Vector3::new(4.0, -4.0, -0.5)];
        schedule(stations(&route, 4.0).expect("route"), &formation, strategy).expect("dance")
    }

    #[test]
    fn steps_follow_the_runner_order() {
        let d = dance(Strategy::Leapfrog);
        let steps = d.steps(|k| k == 0 || k == 5);
        assert_eq!(steps[0].action, Action::Scan { station: 0 });
        // Per cycle: 2 × (move, measure), parent move, 2 measures, fix.
        assert_eq!(steps.len(), 1 + 5 * 8 + 1);
        assert!(matches!(steps[1].action, Action::MoveChild { child: 0, .. }));
        assert_eq!(steps[5].action, Action::MoveParent { from: 0, to: 1 });
        assert_eq!(steps[8].action, Action::Fix { station: 1 });
        assert_eq!(steps.last().map(|s| &s.action), Some(&Action::Scan { station: 5 }));
        assert!(steps.iter().enumerate().all(|(i, s)| s.index == i));
        let hops = dance(Strategy::ParentHops { hops: 2 }).steps(|_| false);
        // Placements in cycles 1, 3, 5; parent moves and fixes in all five.
        let moves = hops.iter().filter(|s| matches!(s.action, Action::MoveChild { .. })).count();
        assert_eq!(moves, 6);
        assert_eq!(hops.len(), 3 * 4 + 5 * 4);
    }

    #[test]
    fn a_pillar_blocks_the_right_step() {
        // Station 2 is at x = 8; its left child stands at (12, 4): the sight
        // line passes (10, 2), the pillar's axis.
        let d = dance(Strategy::Leapfrog);
        let scene = scene_with_pillar();
        let limits = Limits::range(2.0, 100.0);
        let v = check(&d, Some(&scene), &limits, |_| false);
        let blocked: Vec<_> = v.iter().filter(|v| matches!(v.check, Check::LineOfSight { .. })).collect();
        assert!(!blocked.is_empty());
        let first = blocked[0];
        let steps = d.steps(|_| false);
        assert_eq!(
            steps[first.step].action,
            Action::Measure { child: 0, station: 2, phase: Phase::Placement },
            "{first:?}"
        );
        assert_eq!(first.robot, Robot::Child(0));
        assert!(matches!(&first.check, Check::LineOfSight { obstacle } if obstacle == "pillar"));
        assert!((first.value - (2f64.sqrt() * 2.0 - 0.4)).abs() < 0.1, "{}", first.value);
        // Without the scene only ranges are checked: all within [2, 100].
        assert!(check(&d, None, &limits, |_| false).is_empty());
    }

    #[test]
    fn ranges_clearance_separation_tracking_and_slope() {
        let d = dance(Strategy::Leapfrog);
        let scene = scene_with_pillar();
        let mut limits = Limits::range(6.0, 100.0);
        let v = check(&d, None, &limits, |_| false);
        // Every sight line is √(4² + 4² + 0.5²) = 5.68 m or longer at the
        // fix (√(0² + 16 + 0.25)); placements are 5.68 m < 6 m.
        assert!(v.iter().all(|v| v.check == Check::Range && v.limit == 6.0));
        assert_eq!(v.iter().filter(|v| v.value < 6.0).count(), v.len());
        limits = Limits { footprint_radius_m: Some(0.5), track: true, ..Limits::range(2.0, 100.0) };
        let v = check(&d, Some(&scene), &limits, |_| false);
        assert!(v.iter().any(|v| matches!(&v.check, Check::Tracking { obstacle, .. } if obstacle == "pillar")));
        assert!(v.iter().all(|v| !matches!(v.check, Check::Clearance { .. })));
        // The parent driving along y = 1.3 passes 0.3 m from the pillar.
        let near = [Point3::new(0.0, 1.3, 1.5), Point3::new(20.0, 1.3, 1.5)];
        let formation = [Vector3::new(4.0, 4.0, -0.5), Vector3::new(4.0, -4.0, -0.5)];
        let d = schedule(stations(&near, 4.0).expect("route"), &formation, Strategy::Leapfrog).expect("dance");
        let v = check(&d, Some(&scene), &limits, |_| false);
        let c: Vec<_> = v.iter().filter(|v| matches!(v.check, Check::Clearance { .. })).collect();
        assert_eq!(c.len(), 1, "{c:?}");
        assert_eq!((c[0].robot, c[0].station), (Robot::Parent, 3));
        assert!((c[0].value - 0.3).abs() < 0.02, "{}", c[0].value);
        // Separation: children 1 m apart laterally.
        let tight = [Vector3::new(4.0, 0.4, 0.0), Vector3::new(4.0, -0.4, 0.0)];
        let route = [Point3::new(0.0, -10.0, 1.5), Point3::new(8.0, -10.0, 1.5)];
        let close = schedule(stations(&route, 4.0).expect("route"), &tight, Strategy::Leapfrog).expect("dance");
        let v = check(&close, None, &Limits { footprint_radius_m: Some(0.5), ..Limits::range(2.0, 100.0) }, |_| false);
        assert!(v.iter().any(|v| matches!(v.check, Check::Separation { other: Robot::Child(0) })
            && v.robot == Robot::Child(1)
            && (v.value - 0.8).abs() < 1e-9));
        // The parent's move ends 0.4 m abeam of each child (open space too).
        assert!(v.iter().any(|v| matches!(v.check, Check::Separation { other: Robot::Child(0) })
            && v.robot == Robot::Parent
            && (v.value - 0.4).abs() < 1e-9));
        // Slope: a ramp of 1 m over 4 m is 14°.
        let ramp = [Point3::new(0.0, 0.0, 1.5), Point3::new(4.0, 0.0, 2.5)];
        let up = schedule(stations(&ramp, 5.0).expect("route"), &tight, Strategy::Leapfrog).expect("dance");
        let v =
            check(&up, None, &Limits { max_slope_rad: Some(10f64.to_radians()), ..Limits::range(0.0, 100.0) }, |_| {
                false
            });
        assert_eq!(v.len(), 1);
        assert_eq!(v[0].check, Check::Slope);
        assert!((v[0].value - 0.25f64.atan()).abs() < 1e-12);
    }

    #[test]
    fn scan_gaps_and_empty_scans() {
        let d = dance(Strategy::Leapfrog);
        let scene = scene_with_pillar();
        let limits = Limits { scanner_max_range_m: Some(6.0), ..Limits::range(2.0, 100.0) };
        let v = check(&d, Some(&scene), &limits, |k| k % 2 == 0);
        // Scans at stations 0, 2, 4: 8 m apart.
        let gaps: Vec<_> = v.iter().filter(|v| matches!(v.check, Check::ScanGap { .. })).collect();
        assert_eq!(gaps.len(), 2);
        assert!((gaps[0].value - 8.0).abs() < 1e-9);
        assert_eq!(gaps[1].check, Check::ScanGap { previous: 2 });
        // The floor is 1.5 m below: something is in range.
        assert!(v.iter().all(|v| v.check != Check::ScanNothingInRange));
    }
}
