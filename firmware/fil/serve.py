#!/usr/bin/env python3
"""The emulated firmware's UART on a local TCP port: the unmodified firmware-profile ELF on fil.py's
emulated MCU (the self-test build by default: its motor model turns), with each TCP
connection as the cable to its UART, so host tools (acim-monitor, a terminal) talk to the
firmware itself. The emulator runs about 0.2x real time.

    python3 firmware/fil/serve.py [--mode selftest|power-stage] [--tcp 127.0.0.1:7879]
    cargo run --release -p acim-monitor -- --tcp 127.0.0.1:7879
"""
import argparse
import os
import socket
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import fil  # noqa: E402

CHUNK = 25  # periods between two looks at the socket (5 ms of board time)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mode", default="selftest", choices=["selftest", "power-stage"])
    ap.add_argument("--tcp", default="127.0.0.1:7879")
    a = ap.parse_args()
    host, port = a.tcp.rsplit(":", 1)
    elf = fil.default_elf(a.mode)
    if not os.path.exists(elf):
        sys.exit(f"serve.py: {elf} missing: bash firmware/check.sh builds it")
    m = fil.Machine(elf)
    ls = socket.socket()
    ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    ls.bind((host, int(port)))
    ls.listen(1)
    ls.setblocking(False)
    print(f"emulated firmware ({a.mode}) UART on tcp {host}:{ls.getsockname()[1]}", flush=True)
    client = None
    while m.halted is None:
        if client is None:
            try:
                client, _ = ls.accept()
                client.setblocking(False)
                m.tx.clear()  # a new cable sees what the UART sends from now on
            except BlockingIOError:
                pass
        m.run(CHUNK)
        # the emulator's per-period logs grow with every period (its register-write log
        # stops at the boot): keep what serving needs
        del m.isr_instructions[:], m.moe_history[:]
        if client is not None:
            try:
                while True:
                    d = client.recv(4096)
                    if not d:
                        raise ConnectionError("closed")
                    m.send(d.decode("latin-1"))
            except BlockingIOError:
                pass
            except OSError:
                client.close()
                client = None
                continue
            if m.tx:
                try:
                    client.setblocking(True)
                    client.sendall(bytes(m.tx))
                    client.setblocking(False)
                except OSError:
                    client.close()
                    client = None
        m.tx.clear()
    sys.exit(f"serve.py: the emulated MCU halted: {m.halted}")


if __name__ == "__main__":
    main()
