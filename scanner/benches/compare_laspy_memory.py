"""laspy 2.6.1 + lazrs writing a large cloud, for the peak-memory and
throughput comparison in BENCHMARKS.md ("Writing a survey's cloud"): each
case in its own process, peak RSS from getrusage.

    target/ci-venv/bin/python scanner/benches/compare_laspy_memory.py SOURCE.las

SOURCE.las: a run's cloud.las (e.g. the 157-station building at 0.5°).
Cases: the whole cloud in memory, written as LAS and as LAZ (lazrs
parallel), and chunked (1 M points at a time through laspy's chunk
iterator and writer: bounded memory, reading included).
"""
import resource
import subprocess
import sys
import time

CASES = {
    "whole LAS": ("whole", None),
    "whole LAZ (lazrs-parallel)": ("whole", "LazrsParallel"),
    "chunked LAS": ("chunked", None),
    "chunked LAZ (lazrs-parallel)": ("chunked", "LazrsParallel"),
}


def run(source, mode, backend):
    import laspy
    out = "/tmp/laspy-mem.laz" if backend else "/tmp/laspy-mem.las"
    kw = {"laz_backend": getattr(laspy.LazBackend, backend)} if backend else {}
    if mode == "whole":
        las = laspy.read(source)
        n = len(las.points)
        t = time.perf_counter()
        las.write(out, **kw)
        seconds = time.perf_counter() - t
    else:
        t = time.perf_counter()
        n = 0
        with laspy.open(source) as r, laspy.open(out, mode="w", header=r.header, do_compress=bool(backend), **kw) as w:
            for chunk in r.chunk_iterator(1_000_000):
                w.write_points(chunk)
                n += len(chunk)
        seconds = time.perf_counter() - t
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{n} points in {seconds:.2f} s ({n / seconds / 1e6:.1f} M/s), peak RSS {rss_mb:.0f} MB")


if __name__ == "__main__":
    if len(sys.argv) == 4:
        run(sys.argv[1], sys.argv[2], None if sys.argv[3] == "-" else sys.argv[3])
    else:
        for name, (mode, backend) in CASES.items():
            r = subprocess.run([sys.executable, __file__, sys.argv[1], mode, backend or "-"], capture_output=True, text=True)
            print(f"{name}: {r.stdout.strip() or r.stderr.strip()[-300:]}")
