"""Validates real JSON outputs of every cps-survey command against the
schemas in docs/schemas/ (JSON Schema 2020-12, Python's `jsonschema`),
strictly: a key the schema does not describe is an error too.

Usage: check_schemas.py CPS_SURVEY RUN_DIR [REPORT_JSON ...]
(RUN_DIR: a finished run of the hall, which `fuse` and `adjust` reuse;
REPORT_JSON: more runs' report.json to check.)
"""

import json
import pathlib
import subprocess
import sys
import tempfile

import jsonschema

ROOT = pathlib.Path(__file__).resolve().parent.parent
SCHEMAS = ROOT / "docs" / "schemas"
DATA = ROOT / "data"


def strict(node):
    """Every object schema with properties refuses keys it does not name."""
    if isinstance(node, dict):
        if "properties" in node and "unevaluatedProperties" not in node:
            node["unevaluatedProperties"] = False
        for v in node.values():
            strict(v)
    elif isinstance(node, list):
        for v in node:
            strict(v)
    return node


def validator(name):
    schema = strict(json.loads((SCHEMAS / f"{name}.schema.json").read_text()))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def check(name, document, where):
    errors = sorted(validator(name).iter_errors(document), key=lambda e: list(e.absolute_path))
    for e in errors[:10]:
        path = "/".join(str(p) for p in e.absolute_path)
        print(f"{where}: {name} schema: at /{path}: {e.message[:300]}", file=sys.stderr)
    if errors:
        sys.exit(f"{where}: {len(errors)} schema errors")
    for key in ("schema_version", "tool_version"):
        if key not in document:
            sys.exit(f"{where}: no {key}")
    print(f"ok  {name:<10} {where}")


def command(cps, *args, code=0):
    run = subprocess.run([cps, *map(str, args)], capture_output=True, text=True, timeout=900)
    if run.returncode != code:
        sys.exit(f"cps-survey {' '.join(map(str, args))}: exit {run.returncode}\n{run.stderr}")
    lines = [l for l in run.stdout.splitlines() if l.strip()]
    return json.loads(lines[0])


def main():
    cps, run_dir = sys.argv[1], pathlib.Path(sys.argv[2])
    hall = ROOT / "missions" / "examples" / "hall.toml"
    for report in [run_dir / "report.json", *map(pathlib.Path, sys.argv[3:])]:
        check("report", json.loads(report.read_text()), report)
    check("fusion", command(cps, "fuse", run_dir, "--mode", "cps-icp", "--json"), "fuse --json")
    fusion = run_dir / "fusion" / "cps-icp" / "fusion.json"
    check("fusion", json.loads(fusion.read_text()), fusion)
    check("adjust", command(cps, "adjust", run_dir, "--json"), "adjust --json")
    check("predict", command(cps, "predict", hall, "--json"), "predict --json")
    check("plan", command(cps, "plan", hall, "--json"), "plan --json")
    check("montecarlo", command(cps, "montecarlo", hall, "--trials", "20", "--json"), "montecarlo --json")
    check(
        "register",
        command(cps, "register", DATA / "small_gicp_pair" / "source.ply", DATA / "small_gicp_pair" / "target.ply",
                "--json"),
        "register --json",
    )
    with tempfile.TemporaryDirectory() as out:
        check("match", command(cps, "match", DATA / "3dtk_dat", "--out", out, "--json", "--joint-covariance"),
              "match --json --joint-covariance")
        poses = pathlib.Path(out) / "poses.json"
        check("match", json.loads(poses.read_text()), poses)
    check("emulate", command(cps, "emulate", hall, "--json", "--seconds", "1"), "emulate --json")


if __name__ == "__main__":
    main()
