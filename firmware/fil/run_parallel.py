#!/usr/bin/env python3
"""Runs the firmware-in-the-loop suite (test_fil.py) one test class per process, as many
at once as the machine has cores: each class boots its own emulated MCU, so the classes
are independent, and on a 2-core CI machine the suite takes about half its serial time.
Prints each class's unittest output in the suite's order and exits 1 if any failed.

    python3 run_parallel.py [JOBS]
"""
import concurrent.futures
import os
import subprocess
import sys
import time
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))


def classes():
    suite = unittest.defaultTestLoader.loadTestsFromName("test_fil")
    names = []
    for group in suite:
        for test in group:
            name = type(test).__name__
            if name not in names:
                names.append(name)
    return names


def run(name):
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-m", "unittest", "-v", f"test_fil.{name}"],
                       cwd=HERE, capture_output=True, text=True)
    return name, p.returncode, p.stdout + p.stderr, time.monotonic() - t0


def main():
    sys.path.insert(0, HERE)
    os.chdir(HERE)
    jobs = int(sys.argv[1]) if len(sys.argv) > 1 else (os.cpu_count() or 1)
    names = classes()
    with concurrent.futures.ThreadPoolExecutor(max_workers=jobs) as pool:
        results = list(pool.map(run, names))
    failed = 0
    for name, code, out, secs in results:
        print(f"== {name} ({secs:.0f} s)")
        print(out.rstrip())
        failed += code != 0
    print(f"\n{len(results)} test classes in {jobs} processes: {len(results) - failed} passed, "
          f"{failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
