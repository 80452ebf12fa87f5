#!/usr/bin/env python3
"""acim-monitor against the firmware itself: the self-test firmware-profile ELF on the emulated
MCU (serve.py) with its UART on a TCP port, the monitor headless through speed 300 ->
start -> a refused setting -> an unknown command. The monitor connects after the boot's
hello: it must ask `version`, learn protocol 1 and send its commands as $C frames, record
the run, and show the firmware's own (framed) error replies.

    python3 firmware/fil/test_monitor.py <acim-monitor binary>    (about 15 s)
"""
import os
import socket
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
monitor = sys.argv[1]
with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
board = subprocess.Popen([sys.executable, os.path.join(HERE, "serve.py"), "--tcp", f"127.0.0.1:{port}"],
                         stdout=subprocess.PIPE, text=True)
tmp = tempfile.mkdtemp()
try:
    print(board.stdout.readline().strip())
    script = os.path.join(tmp, "script.txt")
    open(script, "w").write("0.1 speed 300\n0.2 start\n0.5 set limits.current_limit 99\n0.6 frobnicate\n")
    csv, screen = os.path.join(tmp, "fil.csv"), os.path.join(tmp, "screen.txt")
    t0 = time.time()
    r = subprocess.run([monitor, "--tcp", f"127.0.0.1:{port}", "--headless", "--until", "2.5",
                        "--script", script, "--record", csv, "--screenshot", screen,
                        "--timeout", "120"], capture_output=True, text=True)
    print(r.stdout.strip(), r.stderr.strip(), f"({time.time() - t0:.1f} s)")
finally:
    board.terminate()
    board.wait()

rows = [l.split(",") for l in open(csv).read().splitlines()[1:]] if r.returncode == 0 else []
text = open(screen).read() if r.returncode == 0 else ""
checks = {
    "the monitor ran to the end": r.returncode == 0,
    "protocol 1 learned from the version reply": "| protocol 1 |" in text,
    "every frame decoded": " 0 bad frames" in r.stdout,
    "the firmware reached 300 rpm on its motor model": any(
        x[3] == "2" and abs(float(x[7]) - 300) < 5 and abs(float(x[6]) - 300) < 5 for x in rows),
    "the firmware's refusal of the setting shown": "err (limits.overcurrent_trip: must be at least current_limit)" in text,
    "the firmware's unknown-command reply shown": "err unknown command (try help)" in text,
    "still running after the refused commands": bool(rows) and rows[-1][3] == "2",
}
for k, v in checks.items():
    print(("ok   " if v else "FAIL ") + k)
sys.exit(0 if all(checks.values()) else 1)
