"""Screenshots of the Test 1 and Test 2 replays at their key moments (docs/figures/).

    python examples/replay_screenshots.py [OUT_DIR]

Runs the paper's two tests as `qpavoid run` does, writes their replays, opens each in
headless Chromium (Debian's, driven by playwright: `pip install ".[dev]"`) and saves the
view at Test 1's closest approach while the robot moves and at Test 2's first stop.
"""

import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
from playwright.sync_api import sync_playwright

from qpavoid.experiments.runs import RunSpec, run_one
from qpavoid.output.run_files import load_log

ARGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-background-networking",
    "--no-first-run",
]
out = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/figures")
out.mkdir(parents=True, exist_ok=True)
with tempfile.TemporaryDirectory() as tmp, sync_playwright() as p:
    browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=ARGS)
    for scenario in ("test1", "test2"):
        run_dir = Path(tmp) / scenario
        run_one(RunSpec(scenario=scenario), run_dir, plots=False)
        log = load_log(run_dir)
        moving = ~log["stopped"]
        if scenario == "test1":  # the closest approach while the robot moves (deflection)
            k = int(np.flatnonzero(moving)[np.argmin(log["distance"].min(axis=1)[moving])])
            name = "replay_test1_closest.png"
        else:  # the first stop
            k = int(np.flatnonzero(log["stopped"])[0])
            name = "replay_test2_stop.png"
        page = browser.new_page(viewport={"width": 1100, "height": 700})
        page.goto((run_dir / "replay.html").resolve().as_uri())
        page.wait_for_function("window.qpavoidReplay !== undefined")
        page.evaluate(f"window.qpavoidReplay.seek({float(log['t'][k])})")
        page.wait_for_timeout(500)
        page.screenshot(path=str(out / name))
        print(f"wrote {out / name} (t = {log['t'][k]:.3f} s)")
    browser.close()
