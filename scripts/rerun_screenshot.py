"""Screenshot a recording in Rerun's own (native) viewer, headless:
`python scripts/rerun_screenshot.py recordings/gas-box.rrd docs/rerun-gas-box.png --time 0.25`.

Needs Vulkan in software (`apt-get install -y mesa-vulkan-drivers`). `rerun FILE --headless
--screenshot-to` shoots before the data has loaded, so this starts the real viewer binary (not
the `rerun` wrapper script, which would leave the viewer running when stopped) on a local port,
opens the file through `ViewerClient`, sets the time cursor, waits for the frame, and shoots.
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
import time
from pathlib import Path

import rerun_cli
from rerun.experimental import ViewerClient


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recording", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--time", type=float, default=0.0, help="sim_time of the shot, seconds")
    parser.add_argument("--size", default="1600x900", help="window size in points")
    parser.add_argument("--settle", type=float, default=8.0, help="seconds to let the viewer draw")
    args = parser.parse_args()
    if not args.recording.is_file():
        sys.exit(f"error: no such recording: {args.recording}")
    binary = Path(rerun_cli.__file__).with_name("rerun")
    port = _free_port()
    log = open(args.out.with_suffix(".log"), "w")
    proc = subprocess.Popen([str(binary), "--headless", "--renderer", "vulkan", "--bind", "127.0.0.1",
                             "--port", str(port), "--window-size", args.size], stdout=log, stderr=subprocess.STDOUT)
    try:
        client = None
        for _ in range(60):
            try:
                client = ViewerClient(f"rerun+http://127.0.0.1:{port}/proxy")
                client.get_state()
                break
            except Exception:  # not listening yet
                client = None
                time.sleep(1.0)
        if client is None:
            sys.exit("error: the Rerun viewer did not start (see the .log beside the output)")
        client.open(str(args.recording.resolve()))
        time.sleep(args.settle)
        client.set_time("sim_time", duration=args.time, play_state="paused")
        time.sleep(args.settle / 2)
        client.save_screenshot(str(args.out))
        print(f"wrote {args.out}")
    finally:
        proc.terminate()
        proc.wait(10)
        log.close()
        args.out.with_suffix(".log").unlink(missing_ok=True)


if __name__ == "__main__":
    main()
