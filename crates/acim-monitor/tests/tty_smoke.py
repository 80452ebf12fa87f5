#!/usr/bin/env python3
"""The interactive monitor on a real pseudo-terminal, as a person uses it: the virtual
board (acim-sim serve, 5x real time), the monitor in a 160x48 terminal recording to CSV,
keys typed: start, speed 300, an invalid setting, Esc (stop), Ctrl-C (quit). Then the
serial path: the monitor opens a pseudo-terminal as its serial port (`--serial`), bridged
to the virtual board, and runs start -> speed -300 headless.

  python3 crates/acim-monitor/tests/tty_smoke.py <target dir>   (after cargo build -p acim-sim -p acim-monitor)
"""
import os, pty, select, socket, struct, subprocess, sys, tempfile, threading, time, tty, fcntl, termios

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
    type_("set limits.current_limit 99\r", 0.5)
    type_("\x1b", 0.5)   # Esc sends stop
    type_("\x03", 1.0)   # Ctrl-C quits
    _, status = os.waitpid(pid, 0)

    # the serial path: a pty as the port, bridged to the board's TCP port
    master, slave = os.openpty()
    tty.setraw(slave)
    link = socket.create_connection(("127.0.0.1", port))

    def up():
        while True:
            try:
                d = os.read(master, 4096)
            except OSError:
                return
            if not d:
                return
            link.sendall(d)

    def down():
        while True:
            d = link.recv(65536)
            if not d:
                return
            os.write(master, d)

    threading.Thread(target=up, daemon=True).start()
    threading.Thread(target=down, daemon=True).start()
    sched = os.path.join(os.path.dirname(csv), "serial-script.txt")
    serial_csv = os.path.join(os.path.dirname(csv), "serial.csv")
    open(sched, "w").write("0.3 start\n0.5 speed -300\n")
    serial = subprocess.run([f"{target}/acim-monitor", "--serial", os.ttyname(slave), "--headless",
                             "--until", "3", "--script", sched, "--record", serial_csv,
                             "--timeout", "30"], capture_output=True, text=True)
    print(serial.stdout.strip(), serial.stderr.strip())
finally:
    board.terminate()
    board.wait()

text = out.decode("utf-8", "replace")
rows = [l.split(",") for l in open(csv).read().splitlines()[1:]]
checks = {
    "exit status 0": os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0,
    "the charts were drawn": "Speed [rpm]" in text and "Currents d/q [A]" in text,
    "the refused setting was shown": "err (limits.overcurrent_trip" in text,
    "the recording was closed": "recorded" in text,
    "the drive ran at 300 rpm": any(r[3] == "2" and abs(float(r[6]) - 300) < 5 for r in rows),
    "Esc stopped it": rows and rows[-1][3] == "0",
    "over the serial port: -300 rpm": serial.returncode == 0 and any(
        r[3] == "2" and abs(float(r[6]) + 300) < 5
        for r in (l.split(",") for l in open(serial_csv).read().splitlines()[1:])),
}
for k, v in checks.items():
    print(("ok   " if v else "FAIL ") + k)
print(f"{len(rows)} rows recorded")
sys.exit(0 if all(checks.values()) else 1)
