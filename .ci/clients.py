"""Independent clients against our emulators (`cps-survey emulate`).

- geocompy 1.0.0 (Leica GeoCOM): its connect sequence, then an ATR fine
  adjust, a distance measurement and the angles + distance (TMC), and the
  one-shot BAP_MeasDistanceAngle; the slope distance must match the
  emulator's truth (child 0 seen from the parent's start).
- pynmea2 1.19.0: parses and checksum-verifies our XDR tilt lines, which
  must match the truth's tilt.

Usage: python clients.py CPS_SURVEY MISSION
"""

import json
import math
import subprocess
import sys
import tempfile

import pynmea2
import serial
from geocompy.communication import open_serial
from geocompy.geo import GeoCom


def fail(message):
    print(f"FAIL: {message}", file=sys.stderr)
    sys.exit(1)


def ok(response, what):
    if response.error.value != 0:
        fail(f"{what}: {response}")
    return response.params


def main():
    exe, mission = sys.argv[1], sys.argv[2]
    truth_file = tempfile.NamedTemporaryFile(suffix=".jsonl", delete=False).name
    emulate = subprocess.Popen(
        [exe, "emulate", mission, "--json", "--truth", truth_file, "--seconds", "120"],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        ports = json.loads(emulate.stdout.readline())
        path = {i["role"]: i["path"] for i in ports["instruments"]}
        baud = {i["role"]: i["baud"] for i in ports["instruments"]}
        with open(truth_file) as f:
            truth = json.loads(f.readline())
        p, c = truth["parent"], truth["children"][0]
        expected_sd = math.dist(p[:3], c)

        with open_serial(path["total-station"], speed=baud["total-station"], timeout=5) as com:
            tps = GeoCom(com)  # LF, COM_NullProc and its other connection RPCs
            ok(tps.aut.fine_adjust(math.radians(1), math.radians(1)), "AUT_FineAdjust")
            ok(tps.tmc.do_measurement(), "TMC_DoMeasure")
            hz, v, sd = ok(tps.tmc.get_simple_measurement(3000), "TMC_GetSimpleMea")
            if abs(sd - expected_sd) > 0.02:
                fail(f"TMC_GetSimpleMea slope distance {sd} m; truth {expected_sd} m")
            hz2, v2, sd2, _ = ok(tps.bap.measure_distance_angle(), "BAP_MeasDistanceAngle")
            if abs(sd2 - expected_sd) > 0.02 or abs(float(v) - float(v2)) > 1e-3:
                fail(f"BAP_MeasDistanceAngle {hz2}, {v2}, {sd2} m; truth {expected_sd} m")
            print(f"geocompy: Hz {float(hz):.6f} rad, V {float(v):.6f} rad, SD {sd:.4f} m "
                  f"(truth {expected_sd:.4f} m)")

        with serial.Serial(path["tilt"], baud["tilt"], timeout=2) as tilt:
            tilt.readline()  # maybe partial
            parsed = 0
            while parsed < 5:
                line = tilt.readline().decode("ascii")
                if not line:
                    fail("no tilt line within 2 s")
                msg = pynmea2.parse(line.strip(), check=True)
                if msg.sentence_type != "XDR" or msg.num_transducers != 2:
                    fail(f"unexpected sentence {line!r}")
                values = {msg.get_transducer(i).id: float(msg.get_transducer(i).value) for i in range(2)}
                roll, pitch = truth["tilt"]
                # PITCH is nose up (= -model pitch), ROLL right side down; 0.01 deg noise.
                if abs(values["ROLL"] - math.degrees(roll)) > 0.06 or abs(values["PITCH"] + math.degrees(pitch)) > 0.06:
                    fail(f"{line!r} vs truth roll {math.degrees(roll)}, pitch {math.degrees(pitch)} deg")
                parsed += 1
            print(f"pynmea2: {parsed} XDR lines checksum-verified, last {line.strip()}")
    finally:
        emulate.terminate()
        emulate.wait()


if __name__ == "__main__":
    main()
