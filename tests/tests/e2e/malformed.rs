//! A corpus of malformed missions: each must exit 2 with a diagnostic at the
//! right file:line:column naming the field.

use tests::Edit;
use tests::{cps_survey, temp_mission};

const GOOD: &str = r#"[mission]
name = "ok"

[team]
children = ["c1", "c2"]

[instruments.total_station]
sigma_distance_mm = 3.0
sigma_hz_arcsec = 5.0
sigma_v_arcsec = 5.0
min_range_m = 4.0
max_range_m = 400.0

[plan]
route_m = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]]
stride_m = 10.0
formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]
"#;

/// (name, edit of GOOD: (from, to), expected "line:column", expected field, expected text in the message)
type Case = (&'static str, (&'static str, &'static str), &'static str, &'static str, &'static str);

const CASES: &[Case] = &[
    (
        "site: a geographic CRS",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\ncrs = \"EPSG:4326\"",
        ),
        "19:7",
        "site.crs",
        "GEOGCS",
    ),
    (
        "site: an EPSG code not known",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\ncrs = \"EPSG:1\"",
        ),
        "19:7",
        "site.crs",
        "EPSG:1 is not in the EPSG definitions",
    ),
    (
        "site: prose for a CRS",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\ncrs = \"UTM 32\"",
        ),
        "19:7",
        "site.crs",
        "expected EPSG:NNNN, EPSG:H+V or a WKT",
    ),
    (
        "site: a CRS in feet (metres would be read as feet)",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\ncrs = \"EPSG:2263\"",
        ),
        "19:7",
        "site.crs",
        "EPSG:2263 has its coordinates in US survey foot (0.3048006096012192 m)",
    ),
    (
        "site: a newline in the local frame's name (it ended a PLY header early)",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\nlocal_frame = \"grid\\nend_header\\n\"",
        ),
        "19:15",
        "site.local_frame",
        "expected a name on one line without control characters",
    ),
    (
        "output: a format listed twice (the survey ran, then failed with no report)",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[output]\nformats = [\"ply\", \"las\", \"ply\"]",
        ),
        "19:26",
        "output.formats[2]",
        "\"ply\" is listed twice: expected each format once",
    ),
    (
        "site: a WKT that only looks like one",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\ncrs = \"PROJCS[\\\"x\\\",AAAA]\"",
        ),
        "19:7",
        "site.crs",
        "has no GEOGCS[…]",
    ),
    (
        "site: a compound CRS whose vertical part is not vertical",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\ncrs = \"EPSG:25832+25833\"",
        ),
        "19:7",
        "site.crs",
        "EPSG:25833 is not a vertical CRS",
    ),
    (
        "site: both a CRS and a local frame",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\ncrs = \"EPSG:25832\"\nlocal_frame = \"grid\"",
        ),
        "19:7",
        "site.crs",
        "both `crs` and `local_frame`",
    ),
    (
        "site: an empty local frame",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\nlocal_frame = \"\"",
        ),
        "19:15",
        "site.local_frame",
        "empty",
    ),
    (
        "site: unknown key",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[site]\ndatum = 1",
        ),
        "19:1",
        "site.datum",
        "unknown key",
    ),
    ("unknown top-level table", ("[plan]", "[plann]\nx = 1\n[plan]"), "14:2", "plann", "unknown key"),
    ("unknown key in mission", ("name = \"ok\"", "name = \"ok\"\nnmae = 1"), "3:1", "mission.nmae", "unknown key"),
    ("missing name", ("name = \"ok\"", ""), "1:1", "mission.name", "missing key"),
    ("empty name", ("name = \"ok\"", "name = \" \""), "2:8", "mission.name", "non-empty"),
    ("name not a string", ("name = \"ok\"", "name = 5"), "2:8", "mission.name", "expected a string"),
    ("missing team", ("[team]\nchildren = [\"c1\", \"c2\"]", ""), "1:1", "team.children", "missing key"),
    ("one child", ("children = [\"c1\", \"c2\"]", "children = [\"c1\"]"), "5:12", "team.children", "at least 2"),
    (
        "duplicate child",
        ("children = [\"c1\", \"c2\"]", "children = [\"c1\", \"c1\"]"),
        "5:19",
        "team.children[1]",
        "duplicate",
    ),
    (
        "child not a string",
        ("children = [\"c1\", \"c2\"]", "children = [\"c1\", 2]"),
        "5:19",
        "team.children[1]",
        "expected a string",
    ),
    (
        "children not an array",
        ("children = [\"c1\", \"c2\"]", "children = \"c1\""),
        "5:12",
        "team.children",
        "expected an array",
    ),
    (
        "missing sigma_distance_mm",
        ("sigma_distance_mm = 3.0\n", ""),
        "7:1",
        "instruments.total_station.sigma_distance_mm",
        "missing key",
    ),
    (
        "negative distance sigma",
        ("sigma_distance_mm = 3.0", "sigma_distance_mm = -3.0"),
        "8:21",
        "instruments.total_station.sigma_distance_mm",
        "expected > 0",
    ),
    (
        "zero hz sigma",
        ("sigma_hz_arcsec = 5.0", "sigma_hz_arcsec = 0"),
        "9:19",
        "instruments.total_station.sigma_hz_arcsec",
        "expected > 0",
    ),
    (
        "nan v sigma",
        ("sigma_v_arcsec = 5.0", "sigma_v_arcsec = nan"),
        "10:18",
        "instruments.total_station.sigma_v_arcsec",
        "finite",
    ),
    (
        "inf v sigma",
        ("sigma_v_arcsec = 5.0", "sigma_v_arcsec = inf"),
        "10:18",
        "instruments.total_station.sigma_v_arcsec",
        "finite",
    ),
    (
        "string sigma",
        ("sigma_hz_arcsec = 5.0", "sigma_hz_arcsec = \"5\""),
        "9:19",
        "instruments.total_station.sigma_hz_arcsec",
        "expected a number",
    ),
    (
        "unknown distance model",
        ("sigma_distance_mm = 3.0", "sigma_distance_mm = 3.0\ndistance_error_model = \"cubic\""),
        "9:24",
        "instruments.total_station.distance_error_model",
        "quadrature",
    ),
    (
        "negative ppm",
        ("sigma_distance_mm = 3.0", "sigma_distance_mm = 3.0\nsigma_distance_ppm = -1"),
        "9:22",
        "instruments.total_station.sigma_distance_ppm",
        "≥ 0",
    ),
    (
        "negative centring",
        ("sigma_distance_mm = 3.0", "sigma_distance_mm = 3.0\ncentring_target_mm = -0.5"),
        "9:22",
        "instruments.total_station.centring_target_mm",
        "≥ 0",
    ),
    (
        "max range below min range",
        ("max_range_m = 400.0", "max_range_m = 2.0"),
        "12:15",
        "instruments.total_station.max_range_m",
        "min_range_m",
    ),
    (
        "unknown instrument key",
        ("sigma_v_arcsec = 5.0", "sigma_v_arcsec = 5.0\nsigma_v_gon = 1"),
        "11:1",
        "instruments.total_station.sigma_v_gon",
        "unknown key",
    ),
    (
        "total_station not a table",
        ("[instruments.total_station]", "[instruments]\ntotal_station = 3\n[x]"),
        "8:17",
        "instruments.total_station",
        "expected a table",
    ),
    ("missing route", ("route_m = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]]\n", ""), "14:1", "plan.route_m", "missing key"),
    (
        "one waypoint",
        ("route_m = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]]", "route_m = [[0.0, 0.0, 0.0]]"),
        "15:11",
        "plan.route_m",
        "at least 2",
    ),
    (
        "waypoint with two numbers",
        ("[100.0, 0.0, 0.0]]", "[100.0, 0.0]]"),
        "15:29",
        "plan.route_m[1]",
        "expected 3 numbers",
    ),
    ("repeated waypoint", ("[100.0, 0.0, 0.0]]", "[0.0, 0.0, 0.0]]"), "15:29", "plan.route_m[1]", "non-zero length"),
    (
        "waypoint with a string",
        ("[100.0, 0.0, 0.0]]", "[100.0, \"a\", 0.0]]"),
        "15:37",
        "plan.route_m[1][1]",
        "expected a number",
    ),
    ("zero stride", ("stride_m = 10.0", "stride_m = 0"), "16:12", "plan.stride_m", "expected > 0"),
    ("negative stride", ("stride_m = 10.0", "stride_m = -4.0"), "16:12", "plan.stride_m", "expected > 0"),
    ("stride as string", ("stride_m = 10.0", "stride_m = \"10 m\""), "16:12", "plan.stride_m", "expected a number"),
    (
        "formation too short",
        ("formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]", "formation_m = [[5.0, 10.0, 0.0]]"),
        "17:15",
        "plan.formation_m",
        "one per child",
    ),
    (
        "formation too long",
        ("[5.0, -10.0, 0.0]]", "[5.0, -10.0, 0.0], [1.0, 5.0, 0.0]]"),
        "17:15",
        "plan.formation_m",
        "one per child",
    ),
    (
        "child straight above",
        ("[5.0, -10.0, 0.0]]", "[0.0, 0.0, 5.0]]"),
        "17:34",
        "plan.formation_m[1]",
        "horizontal offset",
    ),
    (
        "child beyond max range",
        ("[5.0, -10.0, 0.0]]", "[5.0, -500.0, 0.0]]"),
        "17:34",
        "plan.formation_m[1]",
        "max_range_m = 400",
    ),
    (
        "child inside min range",
        ("[5.0, 10.0, 0.0],", "[1.0, 2.0, 0.0],"),
        "17:16",
        "plan.formation_m[0]",
        "min_range_m = 4",
    ),
    ("unknown plan key", ("stride_m = 10.0", "stride_m = 10.0\nstrid_m = 3"), "17:1", "plan.strid_m", "unknown key"),
    (
        "negative start sigma",
        ("stride_m = 10.0", "stride_m = 10.0\nstart_sigma_m = [0.1, -0.1, 0.0]"),
        "17:17",
        "plan.start_sigma_m[1]",
        "≥ 0",
    ),
    (
        "negative acceptance",
        ("[plan]", "[acceptance]\nmax_final_sigma_xy_m = -1\n[plan]"),
        "15:24",
        "acceptance.max_final_sigma_xy_m",
        "expected > 0",
    ),
    ("unknown backend", ("[plan]", "[backend]\nkind = \"real\"\n[plan]"), "15:8", "backend.kind", "unknown value"),
    (
        "serial backend without ports",
        ("[plan]", "[backend]\nkind = \"serial\"\n[plan]"),
        "14:1",
        "backend.serial.tilt",
        "missing key `tilt`",
    ),
    (
        "serial ports on the simulator",
        ("[plan]", "[backend.serial]\ntilt = \"/dev/ttyUSB0\"\n[plan]"),
        "14:1",
        "backend.serial",
        "kind = \"serial\" only",
    ),
    (
        "LMS rate it does not have",
        ("[plan]", "[backend]\nkind = \"serial\"\n[backend.serial]\nscanner_baud = 57600\n[plan]"),
        "17:16",
        "backend.serial.scanner_baud",
        "expected one of [9600, 19200, 38400, 500000]",
    ),
    ("unknown scene", ("[plan]", "[backend]\nscene = \"moon\"\n[plan]"), "15:9", "backend.scene", "\"corridor\""),
    ("fractional seed", ("[plan]", "[backend]\nseed = 1.5\n[plan]"), "15:8", "backend.seed", "whole number"),
    ("one slice", ("[plan]", "[scan]\nslices = 1\n[plan]"), "15:10", "scan.slices", "out of range"),
    ("negative retries", ("[plan]", "[backend]\nmax_retries = -1\n[plan]"), "15:15", "backend.max_retries", "≥ 0"),
    ("too many retries", ("[plan]", "[backend]\nmax_retries = 1000\n[plan]"), "15:15", "backend.max_retries", "≤ 100"),
    (
        "text retry delay",
        ("[plan]", "[backend]\nretry_delay_s = \"1s\"\n[plan]"),
        "15:17",
        "backend.retry_delay_s",
        "number",
    ),
    (
        "scale error too large",
        ("[plan]", "[backend]\nodometry_scale_error_percent = 80\n[plan]"),
        "15:32",
        "backend.odometry_scale_error_percent",
        "≤ 50",
    ),
    ("rerun as text", ("[plan]", "[output]\nrerun = \"yes\"\n[plan]"), "15:9", "output.rerun", "true or false"),
    (
        "negative scan interval",
        ("[plan]", "[scan]\nevery_n_stations = -1\n[plan]"),
        "15:20",
        "scan.every_n_stations",
        "≥ 0",
    ),
    (
        "odd resolution",
        ("[plan]", "[scan]\nresolution_deg = 0.3\n[plan]"),
        "15:18",
        "scan.resolution_deg",
        "1, 0.5 or 0.25",
    ),
    (
        "short lever arm",
        ("[plan]", "[scan]\nbody_from_head_m = [0.0, 0.4]\n[plan]"),
        "15:20",
        "scan.body_from_head_m",
        "3 numbers",
    ),
    ("unknown scan key", ("[plan]", "[scan]\nlever = 1\n[plan]"), "15:1", "scan.lever", "unknown key"),
    (
        "unknown format",
        ("[plan]", "[output]\nformats = [\"ply\", \"obj\"]\n[plan]"),
        "15:19",
        "output.formats[1]",
        "\"e57\"",
    ),
    (
        "zero station error",
        ("[plan]", "[acceptance]\nmax_station_error_m = 0\n[plan]"),
        "15:23",
        "acceptance.max_station_error_m",
        "expected > 0",
    ),
    ("unknown fusion mode", ("[plan]", "[fusion]\nmode = \"slam\"\n[plan]"), "15:8", "fusion.mode", "unknown value"),
    ("zero voxel", ("[plan]", "[fusion]\nvoxel_m = 0\n[plan]"), "15:11", "fusion.voxel_m", "out of range"),
    (
        "degeneracy ratio above 0.1",
        ("[plan]", "[fusion]\ndegeneracy_ratio = 0.5\n[plan]"),
        "15:20",
        "fusion.degeneracy_ratio",
        "out of range",
    ),
    (
        "line ratio of 1",
        ("[plan]", "[fusion]\ndegeneracy_ratio = 0.01\nline_ratio = 1\n[plan]"),
        "16:14",
        "fusion.line_ratio",
        "expected ≥ 0 and ≤ 0.99",
    ),
    (
        "line ratio without blind directions",
        ("[plan]", "[fusion]\nline_ratio = 0.1\n[plan]"),
        "15:14",
        "fusion.line_ratio",
        "expected degeneracy_ratio above 0 with it",
    ),
    (
        "corner ratio above 1",
        ("[plan]", "[fusion]\ncorner_ratio = 1.5\n[plan]"),
        "15:16",
        "fusion.corner_ratio",
        "out of range",
    ),
    (
        "a simultaneous queue of no matches",
        ("[plan]", "[fusion]\nmax_matches_per_scan = 0\n[plan]"),
        "15:24",
        "fusion.max_matches_per_scan",
        "out of range",
    ),
    (
        "fine distance above the coarse one",
        ("[plan]", "[fusion]\nmax_correspondence_m = 0.2\nfine_correspondence_m = 0.5\n[plan]"),
        "16:25",
        "fusion.fine_correspondence_m",
        "expected ≤ max_correspondence_m = 0.2",
    ),
    (
        "scan stations and every_n_stations",
        ("[plan]", "[scan]\nevery_n_stations = 2\nstations = [0, 3]\n[plan]"),
        "16:12",
        "scan.stations",
        "not both",
    ),
    (
        "scan stations out of order",
        ("[plan]", "[scan]\nstations = [3, 1]\n[plan]"),
        "15:12",
        "scan.stations",
        "ascending",
    ),
    (
        "scan station beyond the plan",
        ("[plan]", "[scan]\nstations = [0, 99]\n[plan]"),
        "15:12",
        "scan.stations",
        "station 99 does not exist; expected indices 0 to 10",
    ),
    ("unknown scan head", ("[plan]", "[scan]\nhead = \"spinning\"\n[plan]"), "15:8", "scan.head", "unknown value"),
    (
        "scene and scene_file",
        ("[plan]", "[backend]\nscene = \"hall\"\nscene_file = \"lab.toml\"\n[plan]"),
        "16:14",
        "backend.scene_file",
        "not both",
    ),
    (
        "missing scene file",
        ("[plan]", "[backend]\nscene_file = \"no-such-scene.toml\"\n[plan]"),
        "15:14",
        "backend.scene_file",
        "cannot read scene file",
    ),
    (
        "a robot alone with a formation",
        ("children = [\"c1\", \"c2\"]", "children = []"),
        "17:15",
        "plan.formation_m",
        "no children to place",
    ),
    (
        "hops without parent hops",
        ("stride_m = 10.0", "stride_m = 10.0\nhops = 3"),
        "17:8",
        "plan.hops",
        "applies to strategy = \"parent-hops\" only",
    ),
    (
        "unknown strategy",
        ("stride_m = 10.0", "stride_m = 10.0\nstrategy = \"hop\""),
        "17:12",
        "plan.strategy",
        "unknown value",
    ),
    (
        "formation and formation_m",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\nformation = { kind = \"fan\", radius_m = 10.0, spread_deg = 90.0 }",
        ),
        "17:15",
        "plan.formation_m",
        "not both",
    ),
    (
        "unknown formation kind",
        ("formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]", "formation = { kind = \"circle\" }"),
        "17:22",
        "plan.formation.kind",
        "unknown value",
    ),
    (
        "fan without a radius",
        ("formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]", "formation = { kind = \"fan\", spread_deg = 90.0 }"),
        "17:13",
        "plan.formation.radius_m",
        "missing key",
    ),
    (
        "negative footprint",
        ("children = [\"c1\", \"c2\"]", "children = [\"c1\", \"c2\"]\nfootprint_radius_m = -1"),
        "6:22",
        "team.footprint_radius_m",
        "out of range",
    ),
    (
        "no strategies to search",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[plan.search]\nstrategies = []",
        ),
        "19:14",
        "plan.search.strategies",
        "at least one",
    ),
    (
        "slope too steep",
        ("stride_m = 10.0", "stride_m = 10.0\nmax_slope_deg = 120"),
        "17:17",
        "plan.max_slope_deg",
        "out of range",
    ),
    (
        "pipe axis of no length",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[pipe]\naxis_from_m = [0, 0, 1]\naxis_to_m = [0, 0, 1]\nradius_m = 0.5",
        ),
        "20:13",
        "pipe.axis_to_m",
        "coincide",
    ),
    (
        "pipe without a radius",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[pipe]\naxis_from_m = [0, 0, 1]\naxis_to_m = [9, 0, 1]",
        ),
        "18:1",
        "pipe.radius_m",
        "missing key",
    ),
    (
        "pipe threshold zero",
        (
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]",
            "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[pipe]\naxis_from_m = [0, 0, 1]\naxis_to_m = [9, 0, 1]\nradius_m = 0.5\nthreshold_m = 0",
        ),
        "22:15",
        "pipe.threshold_m",
        "out of range",
    ),
    ("broken TOML", ("[plan]", "[plan"), "14:6", "", "invalid TOML"),
    ("duplicate key", ("stride_m = 10.0", "stride_m = 10.0\nstride_m = 5.0"), "17:1", "", "invalid TOML"),
    ("empty control name", (FORMATION, CONTROL_EMPTY_NAME), "19:8", "control[0].name", "non-empty"),
    ("duplicate control name", (FORMATION, CONTROL_DUPLICATE), "23:14", "control[1].name", "also control[0]"),
    ("NaN control coordinate", (FORMATION, CONTROL_NAN), "20:15", "control[0].position_m[0]", "finite"),
    ("coincident control points", (FORMATION, CONTROL_COINCIDENT), "23:14", "control[1].position_m", "≥ 1 mm apart"),
    ("negative control σ", (FORMATION, CONTROL_NEGATIVE_SIGMA), "21:11", "control[0].sigma_m", "≥ 0"),
    ("control σ of two numbers", (FORMATION, CONTROL_TWO_SIGMAS), "21:11", "control[0].sigma_m", "3 numbers"),
    ("control seen from no station", (FORMATION, CONTROL_FAR), "20:14", "control[0]", "seen from no station"),
    (
        "unknown control_at",
        ("stride_m = 10.0", "stride_m = 10.0\ncontrol_at = \"sometimes\""),
        "17:14",
        "plan.control_at",
        "\"start-end\"",
    ),
    (
        "control_at beyond the plan",
        ("stride_m = 10.0", "stride_m = 10.0\ncontrol_at = [0, 99]"),
        "17:14",
        "plan.control_at",
        "station 99 does not exist",
    ),
    ("mission name a path", ("name = \"ok\"", "name = \"..\""), "2:8", "mission.name", "not a path"),
    (
        "mission name with a separator",
        ("name = \"ok\"", "name = \"../../x\""),
        "2:8",
        "mission.name",
        "path separators",
    ),
    ("mission name too long", ("name = \"ok\"", LONG_NAME), "2:8", "mission.name", "at most 100"),
    ("vertical route segment", ("[100.0, 0.0, 0.0]]", "[0.0, 0.0, 50.0]]"), "15:29", "plan.route_m[1]", "is vertical"),
    ("too many stations", ("stride_m = 10.0", "stride_m = 0.000001"), "16:12", "plan.stride_m", "at most 100001"),
    (
        "a stride of 1e-300 (the count was printed in 230 digits)",
        ("stride_m = 10.0", "stride_m = 1e-300"),
        "16:12",
        "plan.stride_m",
        "give 1.000e302 stations; expected at most 100001",
    ),
    (
        "a route at 3e14 m (issue 34, U1: it validated, then stopped the run's recording)",
        ("route_m = [[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]]", "route_m = [[3e14, 0.0, 0.0], [100.0, 0.0, 0.0]]"),
        "15:13",
        "plan.route_m[0]",
        "300000000000000 m is beyond ±1e8 m: expected coordinates of a survey on Earth",
    ),
    (
        "an integer beyond 64 bits (it was \"not a finite number\")",
        ("formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]", PIPE_HUGE_MIN_POINTS),
        "22:14",
        "pipe.min_points",
        "value 18446744073709551615 is out of range: beyond a 64-bit integer",
    ),
];

const PIPE_HUGE_MIN_POINTS: &str = "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[pipe]\n\
    axis_from_m = [0.0, 0.0, 0.5]\naxis_to_m = [20.0, 0.0, 0.5]\nradius_m = 0.5\nmin_points = 18446744073709551615";

const LONG_NAME: &str =
    "name = \"xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx\"";

const FORMATION: &str = "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]";
const CONTROL_EMPTY_NAME: &str =
    "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[[control]]\nname = \"\"\nposition_m = [10.0, 5.0, 0.0]";
const CONTROL_DUPLICATE: &str = "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[[control]]\nname = \"A\"\n\
    position_m = [10.0, 5.0, 0.0]\n[[control]]\nname = \"A\"\nposition_m = [20.0, 5.0, 0.0]";
const CONTROL_NAN: &str =
    "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[[control]]\nname = \"A\"\nposition_m = [nan, 5.0, 0.0]";
const CONTROL_COINCIDENT: &str = "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[[control]]\nname = \"A\"\n\
    position_m = [10.0, 5.0, 0.0]\n[[control]]\nname = \"B\"\nposition_m = [10.0, 5.0, 0.0005]";
const CONTROL_NEGATIVE_SIGMA: &str = "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[[control]]\nname = \"A\"\n\
    position_m = [10.0, 5.0, 0.0]\nsigma_m = -0.001";
const CONTROL_TWO_SIGMAS: &str = "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[[control]]\nname = \"A\"\n\
    position_m = [10.0, 5.0, 0.0]\nsigma_m = [0.001, 0.002]";
const CONTROL_FAR: &str =
    "formation_m = [[5.0, 10.0, 0.0], [5.0, -10.0, 0.0]]\n[[control]]\nname = \"A\"\nposition_m = [1000.0, 5.0, 0.0]";

#[test]
fn every_malformed_mission_exits_2_at_the_right_place() {
    assert!(CASES.len() >= 30, "the corpus has {} cases", CASES.len());
    // The unmodified mission is fine: each case's failure is its edit's.
    let good = temp_mission(GOOD);
    assert_eq!(cps_survey(["validate".into(), good.path.clone().into_os_string()]).code, 0);
    let mut failures = Vec::new();
    for (name, (from, to), at, field, text) in CASES {
        assert!(GOOD.contains(from), "case {name}: edit does not apply");
        let mission = temp_mission(&GOOD.replacen(from, to, 1));
        let run = cps_survey(["validate".into(), mission.path.clone().into_os_string()]);
        let location = format!("{}:{at}: ", mission.path.display());
        let expected_field = if field.is_empty() { String::new() } else { format!("{field}: ") };
        let found = run.stderr.lines().any(|l| {
            let l = l.trim_start();
            l.starts_with(&location) && l[location.len()..].starts_with(&expected_field) && l.contains(text)
        });
        if run.code != 2 || !found {
            failures
                .push(format!("{name}: exit {} expected {location}{expected_field}…{text}…\n{}", run.code, run.stderr));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn a_mistyped_table_is_one_problem_not_one_per_missing_key() {
    let mission =
        temp_mission(&GOOD.replacen("[instruments.total_station]", "[instruments]\ntotal_station = 3\n[x]", 1));
    let run = cps_survey(["validate".into(), mission.path.clone().into_os_string()]);
    assert_eq!(run.code, 2);
    assert!(!run.stderr.contains("missing key"), "{}", run.stderr);
}

#[test]
fn several_problems_are_reported_at_once() {
    let mission = temp_mission(
        &GOOD.edit("stride_m = 10.0", "stride_m = 0").edit("sigma_hz_arcsec = 5.0", "sigma_hz_arcsec = -5"),
    );
    let run = cps_survey(["predict".into(), mission.path.clone().into_os_string()]);
    assert_eq!(run.code, 2);
    assert!(run.stderr.contains("2 problems found"), "{}", run.stderr);
}

/// `[[control]]` is bounded as the children are: 1,001 control points are
/// refused at once (each adds three unknowns to every fix's dense state;
/// before the bound, and before the state grew once for all of them,
/// 1,000 took minutes to validate).
#[test]
fn more_control_points_than_the_limit_are_refused() {
    let mut text = GOOD.to_string();
    for i in 0..1001 {
        text.push_str(&format!(
            "\n[[control]]\nname = \"C{i}\"\nposition_m = [{}, 5.0, 0.0]\n",
            10.0 + 0.01 * f64::from(i)
        ));
    }
    let mission = temp_mission(&text);
    let run = cps_survey(["validate".into(), mission.path.clone().into_os_string()]);
    assert_eq!(run.code, 2, "{}", run.stderr);
    assert!(run.stderr.contains("control: 1001 control points; expected at most 1000"), "{}", run.stderr);
}
