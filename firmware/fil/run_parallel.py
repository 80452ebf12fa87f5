#!/usr/bin/env python3
"""Runs the firmware-in-the-loop suite (test_fil.py) in parallel processes, as many at once as
the machine has cores. Each test boots its own emulated MCU, so the tests are independent.

The unit of a process is a test class, except for the classes of LONG, whose tests each run
tens of emulated seconds: those run one test per process. The units start longest first
(the expected times of EXPECTED_S, measured; a unit not listed counts as short), so the
cores finish together instead of one of them ending on a long test alone. Prints each
unit's unittest output in the suite's order and exits 1 if any failed.

    python3 run_parallel.py [JOBS]
"""
import concurrent.futures
import os
import subprocess
import sys
import time
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))

# classes whose tests run one per process (each takes long on its own)
LONG = {"SelfTest", "Rearm", "Protection"}
# seconds of each unit on one core of a loaded 2-core machine (what matters is the order)
EXPECTED_S = {
    "SelfTest.test_commission_identifies_the_motor_model_and_applies_it": 347,
    "Rearm.test_commission_runs_to_its_result_on_the_power_stage": 272,
    "Protection.test_a_break_at_any_instant_stays_effective": 92,
    "PowerStage": 41,
    "SelfTest.test_selftest_build_reaches_500_rpm_and_holds_the_fig7_load_step": 38,
    "BitExact": 37,
    "Logs": 31,
    "Protection.test_a_full_rtt_buffer_does_not_starve_the_control_interrupt": 23,
    "Uart": 20,
    "Boot": 18,
    "Settings": 16,
    "Stall": 16,
    "Protection.test_nmi_hardfault_and_unhandled_interrupts_switch_off": 16,
    "Protocol": 11,
}


def units():
    """The units in the suite's order: class names, and Class.test for the LONG classes."""
    suite = unittest.defaultTestLoader.loadTestsFromName("test_fil")
    names = []
    for group in suite:
        for test in group:
            cls = type(test).__name__
            name = f"{cls}.{test._testMethodName}" if cls in LONG else cls
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
    names = units()
    order = sorted(names, key=lambda n: -EXPECTED_S.get(n, 0))
    with concurrent.futures.ThreadPoolExecutor(max_workers=jobs) as pool:
        done = {r[0]: r for r in pool.map(run, order)}
    failed = 0
    for name in names:
        _, code, out, secs = done[name]
        print(f"== {name} ({secs:.0f} s)")
        print(out.rstrip())
        failed += code != 0
    print(f"\n{len(names)} test units in {jobs} processes: {len(names) - failed} passed, "
          f"{failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
