"""PLY files read by CloudCompare's command line (Debian's `cloudcompare`,
headless with QT_QPA_PLATFORM=offscreen): the cloud and, for a pipe run,
the deviation map, exported by CloudCompare as ASCII and compared with the
same files read by plyfile — point counts, coordinates to 0.1 mm, and the
deviation as the scalar field CloudCompare loads (it keeps `scalar_*`
properties as scalar fields, the prefix dropped).

    check_cloudcompare.py RUN_DIR PIPE_RUN_DIR
"""

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import plyfile


def cloudcompare(ply):
    """The cloud as CloudCompare loads it: (header names, values)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "cc.asc"
        env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
        # -GLOBAL_SHIFT 0 0 0: no shift, the coordinates as stored.
        cmd = ["CloudCompare", "-SILENT", "-AUTO_SAVE", "OFF", "-O", "-GLOBAL_SHIFT", "0", "0", "0", str(ply),
               "-C_EXPORT_FMT", "ASC", "-PREC", "6", "-SEP", "SPACE", "-ADD_HEADER", "-SAVE_CLOUDS", "FILE", str(out)]
        run = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
        if run.returncode != 0 or not out.exists():
            sys.exit(f"CloudCompare failed on {ply} (exit {run.returncode}):\n{run.stdout[-2000:]}\n{run.stderr[-2000:]}")
        with out.open() as f:
            names = f.readline().lstrip("/").split()
        return names, np.loadtxt(out, ndmin=2, skiprows=1)


def ours(ply):
    v = plyfile.PlyData.read(str(ply))["vertex"]
    return v, np.column_stack([np.asarray(v[c], dtype=np.float64) for c in "xyz"])


def check_cloud(ply):
    names, cc = cloudcompare(ply)
    v, xyz = ours(ply)
    assert names[:3] == ["X", "Y", "Z"], names
    assert len(cc) == len(xyz), f"{ply}: CloudCompare {len(cc)} points, plyfile {len(xyz)}"
    err = np.abs(cc[:, :3] - xyz).max()
    assert err < 1e-4, f"{ply}: coordinates differ by {err} m"
    print(f"ok  {ply}: CloudCompare {len(cc)} points = plyfile's, coordinates within {err:.1e} m; fields {names}")
    return names, cc, v


def main():
    run, pipe = Path(sys.argv[1]), Path(sys.argv[2])
    check_cloud(run / "cloud.ply")
    check_cloud(pipe / "cloud.ply")
    names, cc, v = check_cloud(pipe / "pipe_deviation.ply")
    assert "deviation_m" in names, f"CloudCompare loaded no deviation scalar field: {names}"
    sf = cc[:, names.index("deviation_m")]
    theirs = np.asarray(v["scalar_deviation_m"], dtype=np.float64)
    err = np.abs(sf - theirs).max()
    assert err < 1e-6, f"the deviation scalar field differs by {err} m"
    assert np.abs(theirs).max() > 1e-3, "a deviation map of zeros proves nothing"
    print(f"ok  deviation_m: CloudCompare's scalar field = the file's to {err:.1e} m "
          f"(|deviation| up to {np.abs(theirs).max() * 1e3:.1f} mm)")


if __name__ == "__main__":
    main()
