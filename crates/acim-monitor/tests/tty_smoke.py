#!/usr/bin/env python3
"""The interactive monitor on a real pseudo-terminal, as a person uses it: the virtual
board (acim-sim serve, 5x real time), the monitor in a 160x48 terminal recording to CSV,
keys typed: start, speed 300, an invalid setting, Esc (stop), Ctrl-C (quit).

  python3 crates/acim-monitor/tests/tty_smoke.py <target dir>   (after cargo build -p acim-sim -p acim-monitor)
"""
import os, pty, select, socket, struct, subprocess, sys, tempfile, time, fcntl, termios

target = sys.argv[1] if len(sys.argv) > 1 else "target/debug"
with socket.socket() as s:
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
addr = f"127.0.0.1:{port}"
board = subprocess.Popen([f"{target}/acim-sim", "serve", "--tcp", addr, "--speed", "5"],
                         stdout=subprocess.DEVNULL)
csv = os.path.join(tempfile.mkdtemp(), "live.csv")
try:
    time.sleep(0.5)
    pid, fd = pty.fork()
    if pid == 0:
        os.environ["TERM"] = "xterm-256color"
        os.execv(f"{target}/acim-monitor", ["acim-monitor", "--tcp", addr, "--record", csv])
    fcntl.ioctl(fd, termios.TIOCSWINSZ, struct.pack("HHHH", 48, 160, 0, 0))
    out = b""

    def pump(t):
        global out
        end = time.time() + t
        while time.time() < end:
            r, _, _ = select.select([fd], [], [], 0.05)
            if r:
                try:
                    out += os.read(fd, 65536)
                except OSError:
                    return

    def type_(text, wait):
        for ch in text:
            os.write(fd, ch.encode())
        pump(wait)

    pump(1.5)
    type_("start\r", 0.5)
    type_("speed 300\r", 2.0)
    type_("set current_limit 99\r", 0.5)
    type_("\x1b", 0.5)   # Esc sends stop
    type_("\x03", 1.0)   # Ctrl-C quits
    _, status = os.waitpid(pid, 0)
finally:
    board.terminate()
    board.wait()

text = out.decode("utf-8", "replace")
rows = [l.split(",") for l in open(csv).read().splitlines()[1:]]
checks = {
    "exit status 0": os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0,
    "the charts were drawn": "Speed [rpm]" in text and "Currents d/q [A]" in text,
    "the refused setting was shown": "err (overcurrent_trip" in text,
    "the recording was closed": "recorded" in text,
    "the drive ran at 300 rpm": any(r[3] == "2" and abs(float(r[6]) - 300) < 5 for r in rows),
    "Esc stopped it": rows and rows[-1][3] == "0",
}
for k, v in checks.items():
    print(("ok   " if v else "FAIL ") + k)
print(f"{len(rows)} rows recorded")
sys.exit(0 if all(checks.values()) else 1)
